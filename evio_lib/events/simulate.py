"""ESIM-style event camera simulator: events from a sequence of rendered images.

Model (thesis §2.2.1; Rebecq, Gehrig, Scaramuzza, "ESIM: an Open Event Camera Simulator", CoRL 2018):
each pixel keeps a reference log intensity ``r`` (the level at which it last fired). With the log intensity
``L = log(I + eps)`` (``eps`` = ``log_eps`` keeps black pixels finite), the pixel fires

* a positive event each time ``L`` rises through ``r + C+`` (then ``r <- r + C+``),
* a negative event each time ``L`` falls through ``r - C-`` (then ``r <- r - C-``).

Between two render samples ``(t0, L0)`` and ``(t1, L1)`` the log intensity is interpolated linearly, so the k-th
crossing of the level ``r + k C`` happens at ``t0 + (r + k C - L0) / (L1 - L0) * (t1 - t0)``; this makes the
timestamps independent of the render rate. Non-idealities: per-pixel threshold mismatch (Gaussian, fixed at
construction), a refractory period, and Poisson background ("shot") and leak noise.

:func:`simulate_events` adds ESIM's adaptive sampling: the next render time is chosen so that no pixel's log
intensity changes by more than ``max_log_change * min(C+, C-)`` between consecutive samples.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np

from evio_lib.events.array import EVENT_DTYPE, empty_events

__all__ = ["EventCameraParams", "EventSimulator", "log_intensity", "simulate_events"]

# A crossing counts when (L - r) / C >= 1 - _CROSS_TOL: absorbs float64 round-off of the accumulated reference,
# so a ramp ending exactly on a threshold fires its last event (at the sample time) instead of one step later.
_CROSS_TOL = 1e-9
# From this many events per step, bucketing by a 16-bit time key before the final stable sort pays off.
_BUCKET_MIN_EVENTS = 4096


@dataclass(frozen=True)
class EventCameraParams:
    """Parameters of the simulated event camera (all log-intensity quantities are natural-log units).

    Attributes:
        contrast_pos: nominal positive contrast threshold C+ (log-intensity rise per ON event).
        contrast_neg: nominal negative contrast threshold C- (log-intensity fall per OFF event).
        contrast_sigma: standard deviation of the per-pixel threshold mismatch; each pixel draws its own C+ and
            C- once, at simulator construction (C = nominal + sigma * N(0, 1), floored at ``min_contrast``).
        refractory_s: after an emitted event a pixel drops crossings for this long [s] (0 disables).
        log_eps: offset in L = log(I + log_eps) so that zero intensity has a finite log.
        background_rate_hz: per-pixel rate of background (shot) noise events, random polarity [Hz].
        leak_rate_hz: per-pixel rate of leak noise events, always positive polarity [Hz].
        min_contrast: floor applied to the mismatched per-pixel thresholds.
    """

    contrast_pos: float = 0.2
    contrast_neg: float = 0.2
    contrast_sigma: float = 0.03
    refractory_s: float = 1e-4
    log_eps: float = 1e-3
    background_rate_hz: float = 0.0
    leak_rate_hz: float = 0.0
    min_contrast: float = 0.01

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if not np.isfinite(value):
                raise ValueError(f"EventCameraParams.{name} must be finite; got {value}")
        for name in ("contrast_pos", "contrast_neg", "log_eps", "min_contrast"):
            if getattr(self, name) <= 0:
                raise ValueError(f"EventCameraParams.{name} must be > 0; got {getattr(self, name)}")
        for name in ("contrast_sigma", "refractory_s", "background_rate_hz", "leak_rate_hz"):
            if getattr(self, name) < 0:
                raise ValueError(f"EventCameraParams.{name} must be >= 0; got {getattr(self, name)}")

    @property
    def needs_rng(self) -> bool:
        """Return True when the simulator draws random numbers (threshold mismatch or noise events)."""
        return self.contrast_sigma > 0 or self.background_rate_hz > 0 or self.leak_rate_hz > 0


def log_intensity(intensity: np.ndarray, log_eps: float = 1e-3) -> np.ndarray:
    """Return L = log(I + log_eps), the log intensity pixels respond to (float32 if I is float32, else float64).

    Keeping float32 renders in float32 halves the memory traffic of :class:`EventSimulator` (its full-image work
    then runs in float32; crossing times are still computed in float64).

    Args:
        intensity: linear intensity image (any shape), finite and >= 0 (nominally in [0, 1]).
        log_eps: positive offset keeping log(0) finite (EventCameraParams.log_eps).

    Reference: thesis §2.2.1 (pixels respond to log-intensity changes); ESIM (Rebecq et al., CoRL 2018).

    >>> log_intensity(np.array([0.0, 1.0]), 1e-3).round(3).tolist()
    [-6.908, 0.001]
    """
    image = np.asarray(intensity)
    if not np.issubdtype(image.dtype, np.number) or np.iscomplexobj(image):
        raise ValueError(f"intensity must hold real numbers; got dtype {image.dtype}")
    if not log_eps > 0:
        raise ValueError(f"log_eps must be > 0; got {log_eps}")
    work = np.float32 if image.dtype == np.float32 else np.float64
    image = image.astype(work, copy=False)
    bad = ~np.isfinite(image) | (image < 0)
    if bad.any():
        i = np.unravel_index(int(np.flatnonzero(bad)[0]), image.shape)
        raise ValueError(
            f"intensity must be finite and >= 0; {int(bad.sum())} bad pixels, first at index {tuple(map(int, i))} "
            f"(value {image[i]})"
        )
    return np.log(image + work(log_eps))  # L = log(I + eps)


def _as_generator(rng: np.random.Generator | int | None, needed: bool, who: str) -> np.random.Generator | None:
    """Return a Generator from ``rng`` (Generator or int seed); raise ValueError when one is needed but missing."""
    if rng is None:
        if needed:
            raise ValueError(
                f"{who}: rng must be a numpy.random.Generator (or an int seed) when contrast_sigma > 0 or a noise "
                f"rate > 0; got None"
            )
        return None
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        return np.random.default_rng(int(rng))
    raise ValueError(f"{who}: rng must be a numpy.random.Generator, an int seed or None; got {type(rng).__name__}")


def _argsort_times(t_ev: np.ndarray, t0: float, dt: float) -> np.ndarray:
    """Return the stable order (ties keep input order) that sorts the timestamps ``t_ev`` (all in [t0, t0 + dt]).

    Large batches are first bucketed by a 16-bit quantised time (numpy's stable sort of uint16 keys is an O(N)
    radix sort), which leaves them nearly sorted; a stable timsort of that sequence then finishes the job in close
    to linear time. The result equals ``np.argsort(t_ev, kind="stable")``.
    """
    if t_ev.shape[0] < _BUCKET_MIN_EVENTS:
        return np.argsort(t_ev, kind="stable")
    key = np.clip((t_ev - t0) * (65535.0 / dt), 0.0, 65535.0).astype(np.uint16)  # bucket = (t - t0) / dt * 65535
    coarse = np.argsort(key, kind="stable")
    return coarse[np.argsort(t_ev[coarse], kind="stable")]


class EventSimulator:
    """Per-pixel ESIM event generator: feed log images with :meth:`step`, get the events in between.

    Args:
        width: sensor width W in pixels (1..65536).
        height: sensor height H in pixels (1..65536).
        params: camera parameters (thresholds, mismatch, refractory period, noise).
        rng: numpy Generator or int seed; required when ``params.contrast_sigma > 0`` or a noise rate is > 0.

    Refractory period (following the open-source ESIM implementation): a crossing less than ``refractory_s``
    after the pixel's last *emitted* event is dropped, but it still moves the reference (the comparator is reset as
    if it had fired), so the pixel stays locked to the signal; only emitted events update the pixel's last-event
    time. Hence ``sum(p * C)`` per pixel tracks the log-intensity change within one threshold only while no event
    was dropped; :attr:`dropped_refractory` counts the dropped crossings, and L - r always stays in (-C-, C+).

    Noise events (background: random polarity; leak: positive) are independent Poisson processes per pixel,
    uniform in time within each step; they neither move the reference nor start a refractory period.

    Reference: thesis §2.2.1; ESIM (Rebecq et al., CoRL 2018), event generation by per-pixel reference and
    linear interpolation.

    >>> sim = EventSimulator(1, 1, EventCameraParams(contrast_sigma=0.0, refractory_s=0.0))
    >>> sim.reset(np.zeros((1, 1)), t=0.0)
    >>> ev = sim.step(np.full((1, 1), 0.5), t=1.0)   # L rises by 0.5 = 2.5 thresholds of 0.2
    >>> ev["t"].round(3).tolist(), ev["p"].tolist()
    ([0.4, 0.8], [1, 1])
    """

    def __init__(
        self,
        width: int,
        height: int,
        params: EventCameraParams = EventCameraParams(),
        rng: np.random.Generator | int | None = None,
    ) -> None:
        if not isinstance(params, EventCameraParams):
            raise ValueError(f"params must be an EventCameraParams; got {type(params).__name__}")
        for name, value in (("width", width), ("height", height)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= value <= 65536:
                raise ValueError(f"{name} must be an integer in [1, 65536] (uint16 pixel coordinates); got {value!r}")
        self.width, self.height, self.params = int(width), int(height), params
        self._rng = _as_generator(rng, params.needs_rng, "EventSimulator")
        shape = (self.height, self.width)
        if params.contrast_sigma > 0:
            # C_pixel = max(C_nominal + sigma * N(0, 1), C_min), drawn once per pixel and polarity
            c_pos = params.contrast_pos + params.contrast_sigma * self._rng.standard_normal(shape)
            c_neg = params.contrast_neg + params.contrast_sigma * self._rng.standard_normal(shape)
            c_pos = np.maximum(c_pos, params.min_contrast)
            c_neg = np.maximum(c_neg, params.min_contrast)
        else:
            c_pos = np.full(shape, float(params.contrast_pos))
            c_neg = np.full(shape, float(params.contrast_neg))
        self._c_pos, self._c_neg = c_pos.ravel(), c_neg.ravel()
        self._c_pos.flags.writeable = False
        self._c_neg.flags.writeable = False
        # slightly narrowed bands for the full-image candidate test L >= r + (1 - 2 tol) C+ or L <= r - (1 - 2 tol) C-
        self._band_pos = (1.0 - 2 * _CROSS_TOL) * self._c_pos
        self._band_neg = (1.0 - 2 * _CROSS_TOL) * self._c_neg
        self._dtype: type = np.float64  # working precision of the stored log images (see reset)
        self._ref: np.ndarray | None = None  # float64 reference levels r
        self._hi: np.ndarray | None = None  # r + band_pos in the working dtype, rounded down (candidate test)
        self._lo: np.ndarray | None = None  # r - band_neg in the working dtype, rounded up
        self._log_prev: np.ndarray | None = None
        self._t_prev: float | None = None
        self._last_event_t = np.full(self.width * self.height, -np.inf)
        #: number of threshold crossings dropped by the refractory period since the last reset
        self.dropped_refractory = 0

    @property
    def thresholds_pos(self) -> np.ndarray:
        """Return the (H, W) per-pixel positive thresholds C+ actually used (read-only)."""
        return self._c_pos.reshape(self.height, self.width)

    @property
    def thresholds_neg(self) -> np.ndarray:
        """Return the (H, W) per-pixel negative thresholds C- actually used (read-only)."""
        return self._c_neg.reshape(self.height, self.width)

    @property
    def reference(self) -> np.ndarray:
        """Return a copy of the (H, W) per-pixel reference log intensities (the level of each pixel's last crossing)."""
        if self._ref is None:
            raise RuntimeError("EventSimulator.reset() has not been called yet")
        return self._ref.reshape(self.height, self.width).copy()

    @property
    def time(self) -> float | None:
        """Return the time [s] of the last image given to :meth:`reset` or :meth:`step` (None before reset)."""
        return self._t_prev

    def _checked_array(self, image: object, name: str) -> np.ndarray:
        """Return ``image`` as an (H, W) real array (no copy), or raise ValueError naming ``name``."""
        arr = np.asarray(image)
        if arr.shape != (self.height, self.width):
            raise ValueError(f"{name} must have shape (H, W) = ({self.height}, {self.width}); got {arr.shape}")
        if arr.dtype.kind not in "fiu":  # float, signed or unsigned integer
            raise ValueError(f"{name} must hold real numbers; got dtype {arr.dtype}")
        return arr

    def _flat_image(self, image: object, name: str, out: np.ndarray) -> np.ndarray:
        """Return the (H, W) image copied into the flat array ``out`` (its dtype); ValueError names ``name``."""
        arr = self._checked_array(image, name)
        np.copyto(out.reshape(self.height, self.width), arr, casting="unsafe")
        if not np.isfinite(out.sum()):  # one cheap pass; NaN/inf anywhere makes the sum non-finite
            bad = ~np.isfinite(out)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise ValueError(
                    f"{name} must be finite; {int(bad.sum())} NaN/inf pixels, first at (row, col) = "
                    f"({i // self.width}, {i % self.width})"
                )
        return out

    def _check_time(self, t: float, name: str = "t") -> float:
        if isinstance(t, bool) or not isinstance(t, (int, float, np.integer, np.floating)) or not math.isfinite(t):
            raise ValueError(f"{name} must be a finite time in seconds; got {t!r}")
        return float(t)

    def reset(self, intensity_or_log: np.ndarray, t: float, *, is_log: bool = True) -> None:
        """Return None; set every pixel's reference (and previous sample) to the given image at time ``t``.

        Args:
            intensity_or_log: (H, W) log intensity (``is_log=True``, as :meth:`step` takes) or linear intensity
                (``is_log=False``; converted with :func:`log_intensity`).
            t: time of the image [s].
            is_log: whether ``intensity_or_log`` already is a log image.

        Also clears the refractory state and :attr:`dropped_refractory`. Thresholds are kept.
        """
        t = self._check_time(t)
        arr = self._checked_array(intensity_or_log, "intensity_or_log")
        if not is_log:
            arr = log_intensity(arr, self.params.log_eps)
        self._dtype = np.float32 if arr.dtype == np.float32 else np.float64
        log_image = self._flat_image(arr, "intensity_or_log", np.empty(arr.size, self._dtype))
        self._ref = log_image.astype(np.float64)
        self._hi, self._lo = self._levels(self._ref, slice(None))
        self._log_prev = log_image
        self._log_spare = np.empty_like(log_image)  # double buffer: step() writes the new sample here
        self._t_prev = t
        self._last_event_t.fill(-np.inf)
        self.dropped_refractory = 0

    def _levels(self, ref: np.ndarray, where: np.ndarray | slice) -> tuple[np.ndarray, np.ndarray]:
        """Return the candidate levels (r + band_pos, r - band_neg) in the working dtype, widened by rounding."""
        hi = ref + self._band_pos[where]
        lo = ref - self._band_neg[where]
        if self._dtype is np.float32:  # round outwards so the float32 test never misses a float64 crossing
            return np.nextafter(hi.astype(np.float32), -np.inf), np.nextafter(lo.astype(np.float32), np.inf)
        return hi, lo

    def step(self, log_image: np.ndarray, t: float) -> np.ndarray:
        """Return the events (dtype EVENT_DTYPE, sorted by t) fired in (t_prev, t] as L moves to ``log_image``.

        Args:
            log_image: (H, W) log intensity L = log(I + eps) at time ``t`` (see :func:`log_intensity`).
            t: its time [s], strictly later than the previous sample.

        Equal timestamps keep row-major pixel order (signal events before noise events). The stored samples keep
        the precision chosen at :meth:`reset` (float32 when that image was float32, else float64); all crossing
        arithmetic is float64.

        Reference: ESIM (Rebecq et al., CoRL 2018): per-pixel reference, linear interpolation between samples;
        thesis §2.2.1.
        """
        if self._ref is None:
            raise RuntimeError("call EventSimulator.reset(image, t) before step()")
        t = self._check_time(t)
        if not t > self._t_prev:
            raise ValueError(f"t must be strictly increasing; got t={t!r} after previous sample t={self._t_prev!r}")
        l1 = self._flat_image(log_image, "log_image", out=self._log_spare)
        t0, dt = self._t_prev, t - self._t_prev
        l0, ref = self._log_prev, self._ref

        # --- which pixels cross: the only full-image work is comparing L1 with the cached levels r +- C ---------
        idx = np.flatnonzero((l1 >= self._hi) | (l1 <= self._lo))
        l1_i, ref_i = l1[idx].astype(np.float64), ref[idx]
        diff = l1_i - ref_i
        up = diff > 0
        step_c = np.copysign(np.where(up, self._c_pos[idx], self._c_neg[idx]), diff)  # signed level step +C+ / -C-
        n = np.floor(diff / step_c + _CROSS_TOL)  # n = floor(|L1 - r| / C) crossings
        fire = n > 0
        if not fire.all():  # candidates inside the rounding margin of the test above
            idx, l1_i, ref_i, up, step_c, n = idx[fire], l1_i[fire], ref_i[fire], up[fire], step_c[fire], n[fire]
        l0_i = l0[idx].astype(np.float64)
        ref_new = ref_i + n * step_c  # r <- r + n * C (also when the refractory period drops some of them)
        ref[idx] = ref_new
        self._hi[idx], self._lo[idx] = self._levels(ref_new, idx)

        # --- crossing times: level_k = r + k*step_c, frac_k = (level_k - L0) / (L1 - L0) = a + k*b ---------------
        inv_dl = 1.0 / (l1_i - l0_i)  # L1 != L0 for every firing pixel (L0 lies strictly inside its band)
        a = (ref_i - l0_i) * inv_dl
        b = step_c * inv_dl  # > 0: fraction of the interval between two successive crossings
        k_count = idx.shape[0]
        n_int = n.astype(np.int64)
        m_total = int(n_int.sum())
        if m_total == k_count:  # common case: one crossing per pixel
            seg = starts = None
            frac = a + b
        else:
            seg = np.repeat(np.arange(k_count), n_int)  # pixel (segment) of each event
            starts = np.cumsum(n_int) - n_int
            k = np.arange(1, m_total + 1) - starts[seg]  # k = 1..n within each pixel
            frac = a[seg] + k * b[seg]
        np.minimum(frac, 1.0, out=frac)
        t_ev = frac * dt
        t_ev += t0  # t_k = t0 + frac_k * (t1 - t0)
        np.minimum(t_ev, t, out=t_ev)  # t0 + (t - t0) may round above t

        # --- refractory period (ESIM rule: drop a crossing closer than refr to the pixel's last emitted event) -----
        keep = None
        refr = self.params.refractory_s
        if refr > 0 and m_total:
            last = self._last_event_t[idx]
            if seg is None:
                keep = (t_ev - last) >= refr
                n_keep = int(np.count_nonzero(keep))
                if n_keep == m_total:
                    self._last_event_t[idx] = t_ev
                else:
                    self._last_event_t[idx[keep]] = t_ev[keep]
            else:
                # crossings of one pixel are evenly spaced by delta = b*dt; the greedy rule keeps the first event
                # at least refr after the last emitted one (index j0), then every m-th one, m = ceil(refr / delta)
                delta = b * dt
                j0 = 1.0 + np.ceil(np.maximum(refr - (t_ev[starts] - last), 0.0) / delta)
                j0 = np.minimum(j0, n + 1.0).astype(np.int64)  # n + 1: no event of this pixel survives
                mm = np.minimum(np.maximum(np.ceil(refr / delta), 1.0), n + 1.0).astype(np.int64)
                kk = k - j0[seg]
                keep = (kk >= 0) & (kk % mm[seg] == 0)
                n_keep = int(np.count_nonzero(keep))
                has = j0 <= n_int
                k_last = j0[has] + mm[has] * ((n_int[has] - j0[has]) // mm[has])
                self._last_event_t[idx[has]] = t_ev[starts[has] + k_last - 1]
            self.dropped_refractory += m_total - n_keep
            if n_keep == m_total:
                keep = None

        # --- (pixel, polarity) of each signal event, then noise ---------------------------------------------------
        pol = up.view(np.int8) * np.int8(2) - np.int8(1)  # +1 up, -1 down
        pix = idx
        if seg is not None:
            pix, pol = idx[seg], pol[seg]
        if keep is not None:
            t_ev, pix, pol = t_ev[keep], pix[keep], pol[keep]
        noise = self._noise_events(t, dt)
        if noise is not None:
            t_ev = np.concatenate([t_ev, noise[0]])
            pix = np.concatenate([pix, noise[1]])
            pol = np.concatenate([pol, noise[2]])

        self._log_spare, self._log_prev = self._log_prev, l1
        self._t_prev = t
        m = t_ev.shape[0]
        if m == 0:
            return empty_events()
        order = _argsort_times(t_ev, t0, dt)
        pix = pix[order]
        out = np.empty(m, dtype=EVENT_DTYPE)
        out["t"] = t_ev[order]
        row = pix // self.width  # y = row, x = column of the row-major pixel index
        out["y"] = row
        out["x"] = pix - row * self.width
        out["p"] = pol[order]
        return out

    def _noise_events(self, t: float, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Return (times, pixel indices, polarities) of background and leak noise in (t - dt, t], or None."""
        p = self.params
        if p.background_rate_hz <= 0 and p.leak_rate_hz <= 0:
            return None
        n_pix = self.width * self.height
        n_bg = int(self._rng.poisson(p.background_rate_hz * n_pix * dt)) if p.background_rate_hz > 0 else 0
        n_leak = int(self._rng.poisson(p.leak_rate_hz * n_pix * dt)) if p.leak_rate_hz > 0 else 0
        total = n_bg + n_leak
        if total == 0:
            return None
        times = t - self._rng.random(total) * dt  # uniform in (t - dt, t]
        pix = self._rng.integers(0, n_pix, total)
        pol = np.ones(total, dtype=np.int8)
        pol[:n_bg] = np.where(self._rng.random(n_bg) < 0.5, 1, -1)  # background: random polarity; leak: +1
        return times, pix, pol


def simulate_events(
    render: Callable[[float], np.ndarray],
    t_start: float,
    t_end: float,
    width: int,
    height: int,
    params: EventCameraParams = EventCameraParams(),
    rng: np.random.Generator | int | None = None,
    max_log_change: float = 0.5,
    dt_min: float = 1e-5,
    dt_max: float = 5e-3,
    progress: bool = False,
    on_sample: Callable[[float, np.ndarray], None] | None = None,
    change_quantile: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Return (events, sample_times): the events of a rendered scene over [t_start, t_end] with adaptive sampling.

    Adaptive sampling (ESIM's brightness-change criterion): with the bound
    B = ``max_log_change * min(contrast_pos, contrast_neg)`` (nominal thresholds), the next step is predicted as
    dt = 0.8 * B / max|dL/dt| from the previous step, clipped to [dt_min, dt_max]. If the rendered image then
    changed by more than B at any pixel, dt is halved and the image re-rendered, so every pair of consecutive
    samples satisfies max|L_k+1 - L_k| <= B, unless dt_min is reached
    (then the sample is accepted and a RuntimeWarning is issued at the end). Float32 renders are simulated with
    float32 log images (see :func:`log_intensity`).

    Args:
        render: ``render(t) -> (H, W)`` linear intensity (float, finite, >= 0; nominally float32 in [0, 1]).
        t_start: first sample time [s] (initialises the pixel references; no events at t_start).
        t_end: last sample time [s], > t_start.
        width: image width W in pixels.
        height: image height H in pixels.
        params: event camera parameters.
        rng: numpy Generator or int seed (required when params draw random numbers; see EventCameraParams).
        max_log_change: bound on the per-sample log change, as a fraction of the smaller nominal threshold.
        dt_min: smallest step [s] (the last step may be shorter to land on t_end).
        dt_max: largest step [s].
        progress: show a tqdm progress bar over simulated time.
        on_sample: called as ``on_sample(t, intensity)`` for every accepted sample (e.g. to record APS frames);
            ``intensity`` is the array ``render`` returned (not copied).
        change_quantile: which quantile of the per-pixel |L_k+1 - L_k| must respect the bound (1.0: the maximum, a
            guarantee for every pixel). Rendered scenes have discontinuities (occlusion boundaries, texture seams) where a
            pixel jumps by a whole log unit however short the step, which would drive every step to ``dt_min``; with e.g.
            0.99 the bound holds for all but the 1 % most-changing pixels, i.e. it follows the smooth texture motion,
            and a jump is timestamped by linear interpolation within that short step (as ESIM's flow-based step does).

    Returns:
        events: (N,) EVENT_DTYPE array sorted by time, all in (t_start, t_end].
        sample_times: (S,) float64 times of the accepted renders, starting with t_start and ending with t_end.

    Reference: ESIM (Rebecq et al., CoRL 2018), adaptive sampling; thesis §2.2.1.

    >>> render = lambda t: np.full((2, 2), 0.1 * np.exp(t) - 1e-3)  # L = log(I + 1e-3) = log(0.1) + t
    >>> p = EventCameraParams(contrast_sigma=0.0, refractory_s=0.0)
    >>> ev, ts = simulate_events(render, 0.0, 1.0, 2, 2, p, dt_max=0.05)
    >>> len(ev), bool(ts[0] == 0.0 and ts[-1] == 1.0)
    (20, True)
    """
    if not callable(render):
        raise ValueError(f"render must be a callable render(t) -> (H, W) image; got {type(render).__name__}")
    for name, value in (("t_start", t_start), ("t_end", t_end), ("dt_min", dt_min), ("dt_max", dt_max),
                        ("max_log_change", max_log_change)):
        is_number = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
        if not is_number or not math.isfinite(value):
            raise ValueError(f"{name} must be a finite number; got {value!r}")
    t_start, t_end = float(t_start), float(t_end)
    if not t_end > t_start:
        raise ValueError(f"t_end must be > t_start; got t_start={t_start}, t_end={t_end}")
    if not 0 < dt_min <= dt_max:
        raise ValueError(f"dt_min and dt_max must satisfy 0 < dt_min <= dt_max; got dt_min={dt_min}, dt_max={dt_max}")
    if not max_log_change > 0:
        raise ValueError(f"max_log_change must be > 0 (a fraction of the contrast threshold); got {max_log_change}")
    if not 0.0 < change_quantile <= 1.0:
        raise ValueError(f"change_quantile must be in (0, 1]; got {change_quantile}")
    if on_sample is not None and not callable(on_sample):
        raise ValueError(f"on_sample must be callable or None; got {type(on_sample).__name__}")

    sim = EventSimulator(width, height, params, rng)
    bound = max_log_change * min(params.contrast_pos, params.contrast_neg)  # B = lambda * min(C+, C-)
    n_pixels = width * height
    rank = min(n_pixels - 1, int(np.ceil(change_quantile * n_pixels)) - 1)  # index of the quantile in sorted |dL|

    def log_change(log_a: np.ndarray, log_b: np.ndarray) -> float:
        """Return the change_quantile quantile of |L_b - L_a| over the pixels (the maximum for 1.0)."""
        diff = np.abs(log_b - log_a).ravel()
        if rank == n_pixels - 1:
            return float(diff.max())
        return float(np.partition(diff, rank)[rank])

    def sample(t: float) -> tuple[np.ndarray, np.ndarray]:
        image = np.asarray(render(t))
        if image.shape != (height, width):
            raise ValueError(f"render(t) must return shape (H, W) = ({height}, {width}); got {image.shape} at t={t}")
        return image, log_intensity(image, params.log_eps)

    image, log_prev = sample(t_start)
    sim.reset(log_prev, t_start)
    if on_sample is not None:
        on_sample(t_start, image)
    times, chunks = [t_start], []
    t, dt_next, n_violations = t_start, float(dt_max), 0
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=t_end - t_start, unit="s", desc="simulate_events")
    try:
        while t < t_end:
            dt_try = min(dt_next, t_end - t)
            while True:
                t_next = t_end if dt_try >= t_end - t else t + dt_try
                image, log_next = sample(t_next)
                change = log_change(log_prev, log_next)  # max (or quantile) over pixels of |L_k+1 - L_k|
                if change <= bound:
                    break
                if dt_try <= dt_min:
                    n_violations += 1
                    break
                dt_try = max(0.5 * dt_try, dt_min)  # halve and re-render
            chunks.append(sim.step(log_next, t_next))
            if on_sample is not None:
                on_sample(t_next, image)
            step = t_next - t
            rate = change / step  # observed max |dL/dt|
            dt_next = dt_max if rate == 0 else float(np.clip(0.8 * bound / rate, dt_min, dt_max))
            if bar is not None:
                bar.update(step)
            t, log_prev = t_next, log_next
            times.append(t)
    finally:
        if bar is not None:
            bar.close()
    if n_violations:
        warnings.warn(
            f"simulate_events: {n_violations} samples exceeded max_log_change even at dt_min={dt_min}; "
            f"lower dt_min for fast scenes",
            RuntimeWarning,
            stacklevel=2,
        )
    chunks = [c for c in chunks if c.size]
    events = np.concatenate(chunks) if chunks else empty_events()
    return events, np.asarray(times, dtype=np.float64)
