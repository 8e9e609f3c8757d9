"""Figures for the Kalman-filter lesson.

- :func:`gaussian_product`: mean and variance of the product of two 1-D Gaussians (the scalar update).
- :func:`plot_kalman_cycle_schematic`: the predict/update cycle drawn: the loop of equations (left) and, on one
  position axis, the last posterior, the prediction (moved and widened), the measurement and the new posterior.
- :func:`plot_track_1d`: a 1-D constant-velocity track: truth, measurements, estimate and its ±2σ band.
- :func:`plot_nees_nis`: average NEES and NIS over Monte-Carlo runs for several filters, with the χ² bands.
- :func:`plot_gate`: an innovation test over time (NIS and the gate) and the error with and without the gate.
- :func:`plot_attitude_filter_run`: the small error-state filter: gyro-bias estimates against the truth, and the
  tilt and yaw standard deviations.

Plotting only; the filters live in the lesson and in :mod:`evio_lib.msckf.error_state_attitude`. Matplotlib is
imported when a figure is made.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evio_lib.evaluation.plots_msckf import _band

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "gaussian_product",
    "plot_kalman_cycle_schematic",
    "plot_track_1d",
    "plot_nees_nis",
    "plot_gate",
    "plot_attitude_filter_run",
]

_SENSOR, _PROCESS, _STATE = "#dbe9f6", "#fde9c9", "#d9f0d3"  # the schematics' palette: inputs, computations, states
_PRIOR, _MEASUREMENT, _POSTERIOR = "tab:blue", "tab:orange", "tab:green"


def _series(value: ArrayLike, name: str, length: int | None = None) -> NDArray[np.float64]:
    """Return ``value`` as a finite float64 (T,) array (of ``length`` when given); raise ValueError otherwise."""
    arr = np.asarray(value, dtype=np.float64)
    expected = "(T,)" if length is None else f"(T,) = ({length},)"
    if arr.ndim != 1 or (length is not None and arr.shape[0] != length) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be a finite array of shape {expected}; got shape {arr.shape}")
    return arr


def _times(t: ArrayLike) -> NDArray[np.float64]:
    arr = _series(t, "t")
    if arr.shape[0] < 2:
        raise ValueError(f"t must hold at least 2 times; got {arr.shape[0]}")
    return arr


def gaussian_product(mean_a: float, var_a: float, mean_b: float, var_b: float) -> tuple[float, float]:
    """Return (mean, variance) of N(mean_a, var_a) N(mean_b, var_b), normalised: the scalar Kalman update.

    mean = mean_a + K (mean_b - mean_a), variance = (1 - K) var_a with K = var_a / (var_a + var_b).

    >>> gaussian_product(0.0, 1.0, 2.0, 1.0)
    (1.0, 0.5)
    """
    if not (var_a > 0 and var_b > 0 and np.isfinite([mean_a, var_a, mean_b, var_b]).all()):
        raise ValueError(f"the variances must be > 0 and all values finite; got var_a={var_a!r}, var_b={var_b!r}")
    gain = var_a / (var_a + var_b)
    return float(mean_a + gain * (mean_b - mean_a)), float((1.0 - gain) * var_a)


def _density(x: NDArray[np.float64], mean: float, var: float) -> NDArray[np.float64]:
    return np.exp(-0.5 * (x - mean) ** 2 / var) / np.sqrt(2.0 * np.pi * var)


def _box(ax: "Axes", x: float, y: float, w: float, h: float, text: str, colour: str,
         fontsize: float = 9.0) -> tuple[float, float, float, float]:
    from matplotlib.patches import FancyBboxPatch

    ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0.02,rounding_size=0.08", facecolor=colour,
                                edgecolor="0.25", linewidth=1.0))
    ax.text(x + w / 2, y + h / 2, text, ha="center", va="center", fontsize=fontsize)
    return x, y, w, h


def _arrow(ax: "Axes", start: Sequence[float], end: Sequence[float], text: str = "",
           connection: str = "arc3", offset: Sequence[float] = (0.0, 0.1), **text_options) -> None:
    ax.annotate("", xy=tuple(end), xytext=tuple(start),
                arrowprops=dict(arrowstyle="-|>", color="0.2", lw=1.3, shrinkA=1, shrinkB=1,
                                connectionstyle=connection))
    if text:
        options = dict(ha="center", va="bottom", fontsize=8.5, color="0.2")
        options.update(text_options)
        ax.text(0.5 * (start[0] + end[0]) + offset[0], 0.5 * (start[1] + end[1]) + offset[1], text, **options)


def plot_kalman_cycle_schematic(x_prev: float = 1.0, var_prev: float = 0.09, velocity: float = 2.0, dt: float = 0.5,
                                q: float = 0.16, z: float = 2.6, var_z: float = 0.16) -> "Figure":
    """Return the Kalman filter's cycle drawn: the equations as a loop (left) and one step on a position axis (right).

    Left: the state's Gaussian N(x, P) goes through the prediction (x = F x, P = F P F^T + Q) and the update with a
    measurement z ~ N(H x, R) (innovation y, its covariance S, the gain K, the Joseph-form P), then the next step.
    Right, computed for a scalar position with a known velocity: the last posterior N(x_prev, var_prev), the prior
    after moving by ``velocity * dt`` and adding ``q`` to the variance, the measurement N(z, var_z) and the
    posterior, their normalised product (:func:`gaussian_product`); the title gives the gain.

    Args:
        x_prev, var_prev: last posterior mean [m] and variance [m²] (> 0).
        velocity, dt: the motion of the prediction [m/s], [s].
        q: process-noise variance added by the prediction [m²] (>= 0).
        z, var_z: measurement [m] and its variance [m²] (> 0).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_kalman_cycle_schematic()
    >>> fig.axes[1].get_xlabel()
    'position [m]'
    """
    import matplotlib.pyplot as plt

    values = np.array([x_prev, var_prev, velocity, dt, q, z, var_z], dtype=np.float64)
    if not np.all(np.isfinite(values)) or var_prev <= 0 or var_z <= 0 or q < 0 or dt <= 0:
        raise ValueError("x_prev, velocity, z must be finite, var_prev, var_z, dt > 0 and q >= 0; got "
                         f"var_prev={var_prev!r}, var_z={var_z!r}, dt={dt!r}, q={q!r}")
    prior_mean, prior_var = x_prev + velocity * dt, var_prev + q  # x = F x, P = F P F^T + Q (F = 1 on position)
    post_mean, post_var = gaussian_product(prior_mean, prior_var, z, var_z)
    gain = prior_var / (prior_var + var_z)

    fig = plt.figure(figsize=(15.0, 5.0))
    grid = fig.add_gridspec(1, 2, width_ratios=(1.1, 1.0))
    ax = fig.add_subplot(grid[0])
    ax.set_xlim(0.0, 12.0)
    ax.set_ylim(0.0, 7.0)
    ax.set_axis_off()
    ax.set_title("one step of the Kalman filter", fontsize=10)
    state = _box(ax, 0.1, 2.9, 2.7, 1.4, "state at k−1\n(posterior)\nN(x, P)", _STATE)
    predict = _box(ax, 4.0, 4.9, 4.4, 1.8, "predict (motion model F, noise Q)\nx = F x\nP = F P Fᵀ + Q",
                   _PROCESS)
    update = _box(ax, 4.0, 0.2, 4.4, 3.2, "update\ny = z − H x   (innovation)\nS = H P Hᵀ + R\nK = P Hᵀ S⁻¹\n"
                  "x = x + K y\nP = (I − KH) P (I − KH)ᵀ + K R Kᵀ", _PROCESS)
    measure = _box(ax, 9.4, 1.1, 2.5, 1.5, "measurement\nz = H x + v\nv ~ N(0, R)", _SENSOR)
    _arrow(ax, (state[0] + state[2] / 2, state[1] + state[3]), (predict[0], predict[1] + predict[3] / 2),
           "k−1 → k", connection="arc3,rad=-0.3", offset=(-0.55, 0.35))
    _arrow(ax, (predict[0] + predict[2] / 2, predict[1]), (update[0] + update[2] / 2, update[1] + update[3]),
           "prior N(x̄, P̄)", offset=(1.0, -0.15))
    _arrow(ax, (measure[0], measure[1] + measure[3] / 2), (update[0] + update[2], measure[1] + measure[3] / 2),
           "z_k")
    _arrow(ax, (update[0], update[1] + 0.8), (state[0] + state[2] / 2, state[1]), "posterior at k",
           connection="arc3,rad=-0.3", offset=(-0.7, -0.9))

    ax2 = fig.add_subplot(grid[1])
    sd = np.sqrt(max(var_prev, prior_var, var_z))
    lo = min(x_prev, prior_mean, z) - 3.5 * sd
    hi = max(x_prev, prior_mean, z) + 3.5 * sd
    x = np.linspace(lo, hi, 600)
    ax2.plot(x, _density(x, x_prev, var_prev), color="0.5", ls="--", label=f"posterior at k−1: N({x_prev:.2f}, "
             f"{var_prev:.2f})")
    ax2.plot(x, _density(x, prior_mean, prior_var), color=_PRIOR, label=f"prior at k (moved by v·Δt, + Q): "
             f"N({prior_mean:.2f}, {prior_var:.2f})")
    ax2.plot(x, _density(x, z, var_z), color=_MEASUREMENT, label=f"measurement: N({z:.2f}, {var_z:.2f})")
    ax2.fill_between(x, _density(x, post_mean, post_var), color=_POSTERIOR, alpha=0.3)
    ax2.plot(x, _density(x, post_mean, post_var), color=_POSTERIOR, lw=2.0,
             label=f"posterior at k: N({post_mean:.2f}, {post_var:.3f})")
    ax2.annotate("", xy=(prior_mean, 0.05), xytext=(x_prev, 0.05),
                 arrowprops=dict(arrowstyle="-|>", color=_PRIOR, lw=1.3))
    ax2.set_xlabel("position [m]")
    ax2.set_ylabel("probability density [1/m]")
    ax2.set_title(f"the product of prior and measurement: gain K = P̄ / (P̄ + R) = {gain:.2f}", fontsize=10)
    ax2.legend(fontsize=8, loc="upper left")
    ax2.set_ylim(0.0, 1.25 * _density(np.array([post_mean]), post_mean, post_var)[0])
    fig.tight_layout()
    return fig


def plot_track_1d(t: ArrayLike, truth: ArrayLike, measurements: ArrayLike, estimate: ArrayLike,
                  sigma: ArrayLike, title: str = "") -> "Figure":
    """Return a 1-D constant-velocity track in two panels: position (with the measurements) and velocity.

    Args:
        t: (T,) times [s].
        truth: (T, 2) true [position m, velocity m/s].
        measurements: (T,) measured positions [m].
        estimate: (T, 2) filter estimates; sigma: (T, 2) their standard deviations (the band is ±2σ).
        title: figure title.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> t = np.linspace(0.0, 1.0, 5); x = np.c_[t, np.ones(5)]
    >>> [ax.get_ylabel() for ax in plot_track_1d(t, x, t, x, np.ones((5, 2))).axes]
    ['position [m]', 'velocity [m/s]']
    """
    import matplotlib.pyplot as plt

    t = _times(t)
    arrays = {}
    for name, value in (("truth", truth), ("estimate", estimate), ("sigma", sigma)):
        arr = np.asarray(value, dtype=np.float64)
        if arr.shape != (t.shape[0], 2) or not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be a finite array of shape (T, 2) = ({t.shape[0]}, 2); got {arr.shape}")
        arrays[name] = arr
    z = _series(measurements, "measurements", t.shape[0])
    fig, axes = plt.subplots(2, 1, figsize=(11, 5.6), sharex=True)
    for i, (ax, unit) in enumerate(zip(axes, ("position [m]", "velocity [m/s]"))):
        ax.plot(t, arrays["truth"][:, i], color="k", lw=1.2, label="truth")
        if i == 0:
            ax.plot(t, z, ".", color=_MEASUREMENT, ms=4, label="measurements z")
        ax.plot(t, arrays["estimate"][:, i], color=_POSTERIOR, lw=1.5, label="filter estimate")
        band = 2.0 * arrays["sigma"][:, i]
        ax.fill_between(t, arrays["estimate"][:, i] - band, arrays["estimate"][:, i] + band, color=_POSTERIOR,
                        alpha=0.2, label="±2σ of the filter")
        ax.set_ylabel(unit)
        ax.legend(fontsize=8, loc="best")
    axes[1].set_xlabel("time [s]")
    if title:
        axes[0].set_title(title)
    fig.tight_layout()
    return fig


def plot_nees_nis(t: ArrayLike, nees: Mapping[str, ArrayLike], nis: Mapping[str, ArrayLike],
                  nees_band: Sequence[float], nis_band: Sequence[float], nees_dof: int, nis_dof: int,
                  n_runs: int, title: str = "") -> "Figure":
    """Return two panels, the average NEES and the average NIS against time, one curve per filter, with χ² bands.

    Args:
        t: (T,) times [s].
        nees, nis: {label: (T,) average over the runs} for each filter (the same labels in both).
        nees_band, nis_band: (lo, hi) 95 % interval of each average (``trajectory_metrics.chi2_bounds``).
        nees_dof, nis_dof: dimension of the state and of the measurement (the expected values).
        n_runs: Monte-Carlo runs in each average (for the labels).
        title: figure title above both panels (none if empty).

    The NEES axis is logarithmic so that filters a factor of ten off stay on the figure.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_nees_nis([0.0, 1.0], {"a": [2.0, 2.1]}, {"a": [1.0, 0.9]}, (1.6, 2.5), (0.7, 1.3), 2, 1, 50)
    >>> [ax.get_yscale() for ax in fig.axes]
    ['log', 'linear']
    """
    import matplotlib.pyplot as plt

    t = _times(t)
    if not nees or set(nees) != set(nis):
        raise ValueError(f"nees and nis must be non-empty mappings with the same labels; got {list(nees)} and "
                         f"{list(nis)}")
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.2))
    for ax, curves, band, dof, name in ((axes[0], nees, nees_band, nees_dof, "NEES"),
                                        (axes[1], nis, nis_band, nis_dof, "NIS")):
        lo, hi = _band(band, f"{name.lower()}_band")
        ax.fill_between(t, lo, hi, color="g", alpha=0.15, label=f"95 % χ² interval ({n_runs} runs)")
        ax.axhline(dof, color="k", lw=0.8, label=f"expected value ({dof})")
        for label, values in curves.items():
            ax.plot(t, _series(values, f"{name.lower()}[{label!r}]", t.shape[0]), lw=1.2, label=label)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(f"average {name} (dimensionless)")
        ax.set_title(f"{name}: {'estimation error (needs the truth)' if name == 'NEES' else 'innovation'}",
                     fontsize=10)
    axes[0].set_yscale("log")
    from matplotlib.ticker import LogFormatter

    axes[0].yaxis.set_major_formatter(LogFormatter())  # plain numbers (5, 6, 7), not 5 x 10^0
    axes[0].yaxis.set_minor_formatter(LogFormatter(labelOnlyBase=False, minor_thresholds=(2, 0.5)))
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=8, frameon=False)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout(rect=(0.0, 0.07 + 0.035 * ((len(labels) - 1) // 3), 1.0, 0.95 if title else 1.0))
    return fig


def plot_gate(t: ArrayLike, nis: ArrayLike, threshold: float, errors: Mapping[str, ArrayLike],
              outlier_time: float) -> "Figure":
    """Return the chi-square gate at work: NIS per update against the threshold (left), errors over time (right).

    Args:
        t: (T,) update times [s].
        nis: (T,) NIS of each update (log axis).
        threshold: the gate, chi2.ppf(p, dof).
        errors: {label: (T,) absolute position error [m]} with and without the gate.
        outlier_time: time of the injected outlier [s] (a vertical line).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_gate([0.0, 1.0], [0.5, 40.0], 6.6, {"no gate": [0.1, 2.0]}, 1.0)
    >>> fig.axes[0].get_yscale(), fig.axes[1].get_ylabel()
    ('log', '|position error| [m]')
    """
    import matplotlib.pyplot as plt

    t = _times(t)
    values = _series(nis, "nis", t.shape[0])
    if not (np.isfinite(threshold) and threshold > 0):
        raise ValueError(f"threshold must be a number > 0; got {threshold!r}")
    if not errors:
        raise ValueError("errors must be a non-empty mapping {label: (T,) errors}")
    fig, axes = plt.subplots(1, 2, figsize=(13, 3.8))
    axes[0].semilogy(t, values, ".", color="0.3", ms=4, label="NIS of each measurement")
    axes[0].axhline(threshold, color="tab:red", lw=1.0, label=f"gate: χ² quantile = {threshold:.2f}")
    axes[0].set_xlabel("time [s]")
    axes[0].set_ylabel("NIS (dimensionless)")
    axes[0].legend(fontsize=8)
    for label, err in errors.items():
        axes[1].plot(t, _series(err, f"errors[{label!r}]", t.shape[0]), lw=1.2, label=label)
    axes[1].set_xlabel("time [s]")
    axes[1].set_ylabel("|position error| [m]")
    axes[1].legend(fontsize=8)
    for ax in axes:
        ax.axvline(outlier_time, color="tab:red", ls=":", lw=1.0)
    fig.tight_layout()
    return fig


def plot_attitude_filter_run(t: ArrayLike, bias_estimate: ArrayLike, bias_truth: ArrayLike, bias_sigma: ArrayLike,
                             tilt_sigma_deg: ArrayLike, yaw_sigma_deg: ArrayLike, title: str = "",
                             log_time: bool = True) -> "Figure":
    """Return the small error-state filter's run: gyro-bias estimates (left) and attitude uncertainty (right).

    Args:
        t: (T,) update times [s].
        bias_estimate, bias_truth, bias_sigma: (T, 3) estimated and true gyro bias and the filter's σ [rad/s]; the
            estimates are drawn with a ±3σ band, the truth dashed.
        tilt_sigma_deg, yaw_sigma_deg: (T,) standard deviation of the tilt (roll/pitch, per axis) and of the yaw
            about gravity [deg], logarithmic axis.
        title: figure title.
        log_time: a logarithmic time axis (t > 0), so that the first seconds, where the bias is learned, and the
            rest of the run are both visible.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> t = np.linspace(0.1, 1.0, 4); b = np.zeros((4, 3))
    >>> fig = plot_attitude_filter_run(t, b, b, b + 1e-3, t + 0.1, t + 1.0)
    >>> fig.axes[1].get_ylabel()
    'standard deviation [deg]'
    """
    import matplotlib.pyplot as plt

    t = _times(t)
    if log_time and t.min() <= 0:
        raise ValueError(f"t must be > 0 for a logarithmic time axis (log_time=True); got t[0] = {t.min()!r}")
    arrays = {}
    for name, value in (("bias_estimate", bias_estimate), ("bias_truth", bias_truth), ("bias_sigma", bias_sigma)):
        arr = np.asarray(value, dtype=np.float64)
        if arr.shape != (t.shape[0], 3) or not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be a finite array of shape (T, 3) = ({t.shape[0]}, 3); got {arr.shape}")
        arrays[name] = arr
    tilt = _series(tilt_sigma_deg, "tilt_sigma_deg", t.shape[0])
    yaw = _series(yaw_sigma_deg, "yaw_sigma_deg", t.shape[0])
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.2))
    for i, (axis, colour) in enumerate(zip("xyz", ("tab:red", "tab:green", "tab:blue"))):
        est = 1e3 * arrays["bias_estimate"][:, i]
        band = 3e3 * arrays["bias_sigma"][:, i]
        axes[0].plot(t, est, color=colour, lw=1.2, label=f"b_g,{axis} estimate")
        axes[0].fill_between(t, est - band, est + band, color=colour, alpha=0.15)
        axes[0].plot(t, 1e3 * arrays["bias_truth"][:, i], color=colour, ls="--", lw=1.0, label=f"b_g,{axis} true")
    axes[0].set_xlabel("time [s]")
    axes[0].set_ylabel("gyroscope bias [mrad/s]")
    axes[0].set_title("bias estimates with ±3σ (shaded) and the truth (dashed)", fontsize=10)
    axes[0].legend(fontsize=7.5, ncol=3)
    axes[1].semilogy(t, tilt, color="tab:purple", label="tilt (roll/pitch), per axis")
    axes[1].semilogy(t, yaw, color="tab:brown", label="yaw about gravity")
    axes[1].set_xlabel("time [s]")
    axes[1].set_ylabel("standard deviation [deg]")
    axes[1].set_title("attitude uncertainty of the filter", fontsize=10)
    axes[1].legend(fontsize=8)
    if log_time:
        for ax in axes:
            ax.set_xscale("log")
            ax.set_xlabel("time [s] (logarithmic)")
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig
