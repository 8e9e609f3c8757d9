"""Figures for the MSCKF lessons (notebooks 09-13): error growth, Monte-Carlo errors against 3-sigma bounds, covariance,
triangulation error against the number of views, NEES against its chi-square band, a filter run against the truth,
the singular values of observability matrices, and two schematics: the update of one feature seen from several
camera clones (notebook 12) and the four unobservable directions of visual-inertial odometry (notebook 13).

Plotting only (plus :func:`correlation_matrix`, the normalised covariance the structure plot shows); the filter lives
in :mod:`evio_lib.msckf`. Matplotlib is imported when a figure is made.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "correlation_matrix",
    "plot_error_growth",
    "plot_monte_carlo_bounds",
    "plot_covariance_structure",
    "plot_triangulation_error",
    "plot_nees",
    "plot_consistency",
    "plot_trajectory_errors",
    "plot_observability_spectrum",
    "plot_feature_update_schematic",
    "plot_unobservable_directions_schematic",
]

_IMU_BLOCKS = ("δθ", "δb_g", "δv", "δb_a", "δp")  # error-state order of thesis Eq. 22 (evio_lib.msckf.state)


def _square_covariance(P: ArrayLike, name: str = "P") -> NDArray[np.float64]:
    """Return P as a finite float64 (n, n) array with a non-negative diagonal; raise ValueError otherwise."""
    try:
        arr = np.asarray(P, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric (n, n) covariance matrix; got {type(P).__name__}") from exc
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1] or arr.shape[0] == 0:
        raise ValueError(f"{name} must have shape (n, n); got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must contain only finite values (no NaN/inf)")
    if np.any(np.diag(arr) < 0.0):
        raise ValueError(f"{name} must have a non-negative diagonal (variances); got min {np.diag(arr).min():.3g}")
    return arr


def correlation_matrix(P: ArrayLike) -> NDArray[np.float64]:
    """Return the correlation matrix ρ (n, n) of a covariance P: ρ_ij = P_ij / sqrt(P_ii P_jj).

    Args:
        P: (n, n) covariance (symmetric, non-negative diagonal). Rows/columns with zero variance get ρ = 0 off the
            diagonal and 1 on it.

    >>> correlation_matrix([[4.0, 1.0], [1.0, 1.0]]).round(2).tolist()
    [[1.0, 0.5], [0.5, 1.0]]
    """
    P = _square_covariance(P)
    sigma = np.sqrt(np.diag(P))
    denom = np.outer(sigma, sigma)
    rho = np.divide(P, denom, out=np.zeros_like(P), where=denom > 0.0)  # ρ_ij = P_ij / (σ_i σ_j)
    np.fill_diagonal(rho, 1.0)
    return np.clip(rho, -1.0, 1.0)


def plot_error_growth(t: ArrayLike, errors: Mapping[str, ArrayLike], ylabel: str = "position error [m]",
                      title: str = "", loglog: bool = False,
                      guides: Sequence[tuple[float, float, str]] = ()) -> "Figure":
    """Return a figure of error curves against time (one line per entry of ``errors``), optionally log-log.

    Args:
        t: (T,) times [s].
        errors: label -> (T,) error magnitudes (e.g. |p_est - p_true|) [any unit, >= 0].
        ylabel: y-axis label; title: figure title.
        loglog: log-log axes (then a power law c t^k is a straight line of slope k; only t > 0, e > 0 are drawn).
        guides: dashed reference power laws, each (power k, value at t[-1], label): y = value (t / t[-1])^k.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_error_growth([0.0, 1.0, 2.0], {"a": [0.0, 0.1, 0.4]}, loglog=True, guides=[(2, 0.4, "t^2")])
    >>> len(fig.axes[0].lines)
    2
    """
    import matplotlib.pyplot as plt

    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1 or t.shape[0] < 2 or not np.all(np.isfinite(t)):
        raise ValueError(f"t must be a finite array of shape (T,), T >= 2; got shape {t.shape}")
    if not isinstance(errors, Mapping) or not errors:
        raise ValueError(f"errors must be a non-empty mapping label -> (T,) array; got {type(errors).__name__}")
    curves = {}
    for label, value in errors.items():
        e = np.asarray(value, dtype=np.float64)
        if e.shape != t.shape:
            raise ValueError(f"errors[{label!r}] must have shape (T,) = {t.shape} like t; got {e.shape}")
        curves[label] = e
    fig, ax = plt.subplots(figsize=(7, 4))
    for label, e in curves.items():
        keep = (t > 0) & (e > 0) if loglog else np.ones_like(t, dtype=bool)
        ax.plot(t[keep], e[keep], lw=1.5, label=label)
    t_end = t[-1]
    for k, (power, value, label) in enumerate(guides):
        if not (np.isfinite(power) and np.isfinite(value) and value > 0 and t_end > 0):
            raise ValueError(f"guides must be (power, value > 0 at t[-1] > 0, label); got {(power, value, label)!r}")
        tg = t[t > 0]
        style = ("k--", "k:", "k-.")[k % 3]  # each guide its own style, so the legend tells them apart
        ax.plot(tg, value * (tg / t_end) ** power, style, lw=1.0, alpha=0.8, label=label)  # y = v (t / t_end)^k
    if loglog:
        ax.set_xscale("log")
        ax.set_yscale("log")
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_monte_carlo_bounds(t: ArrayLike, errors: ArrayLike, sigma: ArrayLike, labels: Sequence[str],
                            n_sigma: float = 3.0, max_runs: int = 30, title: str = "") -> "Figure":
    """Return a figure with one panel per error component: Monte-Carlo error traces inside the filter's ±n σ bounds.

    Args:
        t: (T,) times [s].
        errors: (R, T, d) errors true - estimate of R runs (d components, e.g. δθ_xyz and δp_xyz).
        sigma: (T, d) standard deviations the filter predicts, sqrt(diag P).
        labels: d component names (y-axis labels, with units).
        n_sigma: width of the bounds (3 by default: a consistent filter keeps ~99.7 % of the errors inside).
        max_runs: at most this many traces are drawn (all runs enter the empirical ±n std curve).
        title: figure title.

    Solid red: ±n σ of the filter; dashed blue: ±n times the sample standard deviation over the runs.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_monte_carlo_bounds([0.0, 1.0], np.zeros((4, 2, 1)), np.ones((2, 1)), ["x [m]"])
    >>> fig.axes[0].lines[-2].get_ydata().tolist()      # +3 sigma
    [3.0, 3.0]
    """
    import matplotlib.pyplot as plt

    t = np.asarray(t, dtype=np.float64)
    e = np.asarray(errors, dtype=np.float64)
    s = np.asarray(sigma, dtype=np.float64)
    if t.ndim != 1:
        raise ValueError(f"t must have shape (T,); got {t.shape}")
    if e.ndim != 3 or e.shape[1] != t.shape[0] or e.shape[0] < 1:
        raise ValueError(f"errors must have shape (R, T, d) with T = {t.shape[0]}; got {e.shape}")
    d = e.shape[2]
    if s.shape != (t.shape[0], d):
        raise ValueError(f"sigma must have shape (T, d) = ({t.shape[0]}, {d}); got {s.shape}")
    if np.any(s < 0) or not np.all(np.isfinite(s)):
        raise ValueError("sigma must contain finite standard deviations >= 0")
    if len(labels) != d:
        raise ValueError(f"labels must name the d = {d} components; got {len(labels)} labels")
    if not (np.isfinite(n_sigma) and n_sigma > 0):
        raise ValueError(f"n_sigma must be a finite number > 0; got {n_sigma!r}")
    ncols = 3 if d % 3 == 0 else d
    nrows = int(np.ceil(d / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(4 * ncols, 2.8 * nrows), sharex=True, squeeze=False)
    spread = n_sigma * e.std(axis=0)  # empirical ±n std over the runs
    for k, ax in enumerate(axes.ravel()):
        if k >= d:
            ax.set_visible(False)
            continue
        for r in range(min(e.shape[0], max_runs)):
            ax.plot(t, e[r, :, k], color="0.6", lw=0.6, alpha=0.7)
        ax.plot(t, spread[:, k], "b--", lw=1.0)
        ax.plot(t, -spread[:, k], "b--", lw=1.0)
        ax.plot(t, n_sigma * s[:, k], "r", lw=1.6)
        ax.plot(t, -n_sigma * s[:, k], "r", lw=1.6)
        ax.set_ylabel(labels[k])
        ax.grid(True, alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color="0.6", lw=0.8, label=f"Monte-Carlo runs ({min(e.shape[0], max_runs)} drawn)"),
               Line2D([], [], color="r", lw=1.6, label=f"filter ±{n_sigma:g}σ"),
               Line2D([], [], color="b", ls="--", lw=1.0, label=f"sample ±{n_sigma:g} std over {e.shape[0]} runs")]
    axes[0, 0].legend(handles=handles, fontsize=7, loc="upper left")
    fig.suptitle(title or f"{e.shape[0]} Monte-Carlo runs (grey), filter ±{n_sigma:g}σ (red), "
                          f"sample ±{n_sigma:g} std (blue dashed)", fontsize=10)
    fig.tight_layout()
    return fig


def plot_covariance_structure(P: ArrayLike, correlation: bool = True, title: str = "") -> "Figure":
    """Return an image of an MSCKF covariance (15 + 6N)²: correlations (or log10 |P|) with the state blocks marked.

    Args:
        P: (15 + 6N, 15 + 6N) error-state covariance in the order [δθ, δb_g, δv, δb_a, δp, (δθ_Ci, δp_Ci)_i]
            (thesis Eq. 26; ``evio_lib.msckf.state``).
        correlation: show ρ = correlation_matrix(P) in [-1, 1] (True) or log10 |P_ij| (False).
        title: figure title.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_covariance_structure(np.eye(27))
    >>> fig.axes[0].images[0].get_array().shape
    (27, 27)
    """
    import matplotlib.pyplot as plt

    P = _square_covariance(P)
    n = P.shape[0]
    if n < 15 or (n - 15) % 6:
        raise ValueError(f"P must have shape (15 + 6N, 15 + 6N); got {P.shape}")
    n_cam = (n - 15) // 6
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    if correlation:
        image = ax.imshow(correlation_matrix(P), cmap="coolwarm", vmin=-1.0, vmax=1.0, interpolation="nearest")
        label = "correlation ρ_ij"
    else:
        with np.errstate(divide="ignore"):
            logabs = np.log10(np.abs(P))  # log10 |P_ij|; exact zeros -> -inf, shown as the lowest colour
        finite = logabs[np.isfinite(logabs)]
        low = float(finite.min()) if finite.size else 0.0
        image = ax.imshow(np.where(np.isfinite(logabs), logabs, low), cmap="viridis", interpolation="nearest")
        label = "log10 |P_ij|"
    fig.colorbar(image, ax=ax, label=label, fraction=0.046)
    edges = [3 * k for k in range(1, 5)] + [15 + 6 * i for i in range(n_cam)]
    for x in edges:
        width = 1.4 if x >= 15 else 0.5
        ax.axhline(x - 0.5, color="k", lw=width)
        ax.axvline(x - 0.5, color="k", lw=width)
    centres = [3 * k + 1 for k in range(5)] + [15 + 6 * i + 2.5 for i in range(n_cam)]
    names = list(_IMU_BLOCKS) + [f"C{i + 1}" for i in range(n_cam)]
    ax.set_xticks(centres)
    ax.set_xticklabels(names, rotation=90, fontsize=7)
    ax.set_yticks(centres)
    ax.set_yticklabels(names, fontsize=7)
    ax.set_title(title or f"error-state covariance, 15 + 6·{n_cam} = {n} states")
    fig.tight_layout()
    return fig


def plot_triangulation_error(view_counts: ArrayLike, median_error: ArrayLike, noise_levels_px: ArrayLike,
                             title: str = "", standard_error: ArrayLike | None = None) -> "Figure":
    """Return the median triangulation error [cm] against the number of views, one line per pixel-noise level.

    Args:
        view_counts: (V,) numbers of views M of the track (x axis).
        median_error: (L, V) median position error of the triangulated feature [m], row l for noise level l.
        noise_levels_px: (L,) standard deviation of the pixel noise of each row [px] (the legend).
        title: figure title.
        standard_error: optional (L, V) standard errors of the medians [m] (e.g. from a bootstrap), drawn as
            ±2 standard-error bars: two medians whose bars overlap are not ranked by this Monte-Carlo.

    Reference: thesis §3.3.7 (Eqs. 68-71, Gauss-Newton triangulation in inverse depth).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_triangulation_error([2, 3, 5], [[0.3, 0.2, 0.15]], [1.0])
    >>> [float(y) for y in fig.axes[0].lines[0].get_ydata()]
    [30.0, 20.0, 15.0]
    """
    import matplotlib.pyplot as plt

    views = np.asarray(view_counts, dtype=np.float64)
    errors = np.asarray(median_error, dtype=np.float64)
    noise = np.asarray(noise_levels_px, dtype=np.float64)
    if views.ndim != 1 or views.size == 0 or np.any(views < 1):
        raise ValueError(f"view_counts must be a non-empty (V,) array of counts >= 1; got {views.tolist()}")
    if noise.ndim != 1 or noise.size == 0:
        raise ValueError(f"noise_levels_px must be a non-empty (L,) array; got shape {noise.shape}")
    if errors.shape != (noise.size, views.size):
        raise ValueError(f"median_error must have shape (L, V) = ({noise.size}, {views.size}), one row per noise "
                         f"level and one column per view count; got {errors.shape}")
    bars = None
    if standard_error is not None:
        bars = np.asarray(standard_error, dtype=np.float64)
        if bars.shape != errors.shape or np.any(bars < 0) or not np.all(np.isfinite(bars)):
            raise ValueError(f"standard_error must hold finite values >= 0 of shape (L, V) = {errors.shape}; got "
                             f"shape {bars.shape}")
    fig, ax = plt.subplots(figsize=(8, 3.5))
    for k, (noise_px, row) in enumerate(zip(noise, errors)):
        ax.plot(views, 100 * row, "o-", color=f"C{k}", label=f"{noise_px:g} px noise")  # m -> cm
        if bars is not None:
            ax.errorbar(views, 100 * row, yerr=200 * bars[k], fmt="none", ecolor=f"C{k}", capsize=3, lw=1.0)
    if bars is not None:
        ax.plot([], [], color="0.3", marker="|", ls="none", ms=10, label="±2 standard errors of the median")
    ax.set(xlabel="number of views (same time span)", ylabel="median position error [cm]", title=title)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)  # beside the axes: covers no curve
    fig.tight_layout()
    return fig


def _series(t: np.ndarray, value: ArrayLike, name: str) -> np.ndarray:
    """Return value as a float64 (T,) array like t; raise ValueError naming ``name`` otherwise."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != t.shape:
        raise ValueError(f"{name} must have shape (T,) = {t.shape} like t; got {arr.shape}")
    return arr


def _band(band: tuple[float, float], name: str) -> tuple[float, float]:
    """Return (lo, hi) as floats with 0 <= lo < hi; raise ValueError otherwise."""
    try:
        lo, hi = (float(b) for b in band)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a (lo, hi) pair of numbers; got {band!r}") from exc
    if not (0.0 <= lo < hi and np.isfinite(hi)):
        raise ValueError(f"{name} must satisfy 0 <= lo < hi; got ({lo}, {hi})")
    return lo, hi


def plot_nees(t: ArrayLike, nees: ArrayLike, band: tuple[float, float], dof: int, n_runs: int,
              title: str = "") -> "Figure":
    """Return a figure of an average NEES curve against time with its expected value and 95 % chi-square band.

    Args:
        t: (T,) times [s].
        nees: (T,) NEES averaged over the Monte-Carlo runs.
        band: (lo, hi) 95 % band of the average NEES (``trajectory_metrics.chi2_bounds(dof, n_runs)``).
        dof: degrees of freedom of one NEES value (its expected value); n_runs: runs in the average (for the labels).
        title: figure title.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_nees([0.0, 1.0], [5.0, 7.0], (4.6, 7.6), dof=6, n_runs=20)
    >>> list(fig.axes[0].lines[1].get_ydata())      # the expected value
    [6, 6]
    """
    import matplotlib.pyplot as plt

    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1 or t.shape[0] < 2:
        raise ValueError(f"t must have shape (T,), T >= 2; got {t.shape}")
    e = _series(t, nees, "nees")
    lo, hi = _band(band, "band")
    fig, ax = plt.subplots(figsize=(7, 3))
    ax.plot(t, e, label=f"average NEES over {n_runs} runs")
    ax.axhline(dof, color="k", lw=0.8, label=f"expected value ({dof})")
    ax.fill_between(t, lo, hi, color="g", alpha=0.2, label="95 % χ² interval")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("NEES (dimensionless)")
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return fig


def plot_consistency(t: ArrayLike, curves: Mapping[str, Mapping[str, ArrayLike]], pose_band: tuple[float, float],
                     yaw_band: tuple[float, float], n_runs: int, title: str = "") -> "Figure":
    """Return a figure comparing filter variants: average pose NEES, average yaw NEES and yaw standard deviation.

    Args:
        t: (T,) image times [s].
        curves: variant label -> {"pose": (T,) average 6-DoF pose NEES, "yaw": (T,) average 1-DoF yaw NEES,
            "yaw_sigma_deg": (T,) the filter's yaw standard deviation, averaged over the runs [deg]}.
        pose_band, yaw_band: (lo, hi) 95 % bands of the averages (``chi2_bounds(6, n_runs)``, ``chi2_bounds(1, n_runs)``).
        n_runs: Monte-Carlo runs in each average (for the labels).
        title: figure title.

    NEES panels are logarithmic with the band in grey; a yaw standard deviation that *falls* although nothing observes
    yaw is spurious information (thesis §3.3.8).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> c = {"OC on": {"pose": [6.0, 6.0], "yaw": [1.0, 1.0], "yaw_sigma_deg": [3.0, 3.0]}}
    >>> fig = plot_consistency([0.0, 1.0], c, (4.6, 7.6), (0.5, 1.7), n_runs=20)
    >>> [ax.get_title() for ax in fig.axes]
    ['average pose NEES (6 DoF)', 'average yaw NEES (1 DoF)', 'yaw standard deviation']
    """
    import matplotlib.pyplot as plt

    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1 or t.shape[0] < 2:
        raise ValueError(f"t must have shape (T,), T >= 2; got {t.shape}")
    if not isinstance(curves, Mapping) or not curves:
        raise ValueError(f"curves must be a non-empty mapping label -> {{'pose', 'yaw', 'yaw_sigma_deg'}}; "
                         f"got {type(curves).__name__}")
    keys = ("pose", "yaw", "yaw_sigma_deg")
    data = {}
    for label, c in curves.items():
        missing = [k for k in keys if k not in c]
        if missing:
            raise ValueError(f"curves[{label!r}] lacks {missing}; expected the keys {list(keys)}")
        data[label] = [_series(t, c[k], f"curves[{label!r}][{k!r}]") for k in keys]
    bands = (_band(pose_band, "pose_band"), _band(yaw_band, "yaw_band"))
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
    for k, (label, (pose, yaw, sigma)) in enumerate(data.items()):
        style = f"C{k}-"
        axes[0].semilogy(t, pose, style, label=label)
        axes[1].semilogy(t, yaw, style, label=label)
        axes[2].plot(t, sigma, style, label=label)
    for ax, (lo, hi), name in zip(axes[:2], bands, ("average pose NEES (6 DoF)", "average yaw NEES (1 DoF)")):
        ax.axhspan(lo, hi, color="0.8", label=f"95 % band, {n_runs} runs")
        ax.set(xlabel="t [s]", ylabel="average NEES (dimensionless, log scale)", title=name)
    axes[2].set(xlabel="t [s]", ylabel="σ_yaw [deg]", title="yaw standard deviation")
    axes[2].set_ylim(bottom=0.0)
    for ax in axes:
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_trajectory_errors(t: ArrayLike, p_gt: ArrayLike, estimates: Mapping[str, ArrayLike], sigma: ArrayLike,
                           n_sigma: float = 3.0, margin: float = 0.5) -> "Figure":
    """Return a 2 x 3 figure: position per axis against the truth (top), the first estimate's error in cm with ±nσ (bottom).

    Args:
        t: (T,) times [s].
        p_gt: (T, 3) true positions [m].
        estimates: label -> (T, 3) estimated positions [m]; the first entry is the filter whose error is shown.
        sigma: (T, 3) the first estimate's position standard deviations [m].
        n_sigma: width of the error band; margin: the top row shows the truth's range ± margin [m] (estimates that
            leave it, e.g. dead reckoning, are clipped by the axes).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> t = np.linspace(0.0, 1.0, 5); p = np.zeros((5, 3))
    >>> fig = plot_trajectory_errors(t, p, {"MSCKF": p + 0.01}, np.full((5, 3), 0.01))
    >>> len(fig.axes)
    6
    """
    import matplotlib.pyplot as plt

    t = np.asarray(t, dtype=np.float64)
    gt = np.asarray(p_gt, dtype=np.float64)
    s = np.asarray(sigma, dtype=np.float64)
    if t.ndim != 1 or t.shape[0] < 2:
        raise ValueError(f"t must have shape (T,), T >= 2; got {t.shape}")
    if gt.shape != (t.shape[0], 3):
        raise ValueError(f"p_gt must have shape (T, 3) = ({t.shape[0]}, 3); got {gt.shape}")
    if s.shape != gt.shape or np.any(s < 0) or not np.all(np.isfinite(s)):
        raise ValueError(f"sigma must be finite standard deviations >= 0 of shape ({t.shape[0]}, 3); got {s.shape}")
    if not isinstance(estimates, Mapping) or not estimates:
        raise ValueError(f"estimates must be a non-empty mapping label -> (T, 3) positions; got {type(estimates).__name__}")
    est = {}
    for label, value in estimates.items():
        arr = np.asarray(value, dtype=np.float64)
        if arr.shape != gt.shape:
            raise ValueError(f"estimates[{label!r}] must have shape (T, 3) = {gt.shape}; got {arr.shape}")
        est[label] = arr
    fig, axes = plt.subplots(2, 3, figsize=(12, 5.5), sharex=True)
    first = next(iter(est))
    styles = ["C0--", "C3:", "C2-.", "C4--"]
    for j, name in enumerate("xyz"):
        axes[0, j].plot(t, gt[:, j], "k-", label="ground truth")
        for k, (label, p) in enumerate(est.items()):
            axes[0, j].plot(t, p[:, j], styles[k % len(styles)], label=label)
        axes[0, j].set_ylim(gt[:, j].min() - margin, gt[:, j].max() + margin)
        axes[0, j].set_title(f"position {name} [m]")
        axes[0, j].set_ylabel(f"{name} [m]")
        axes[1, j].plot(t, 100 * (est[first][:, j] - gt[:, j]), "C0-", label=f"{first} error")
        axes[1, j].fill_between(t, -100 * n_sigma * s[:, j], 100 * n_sigma * s[:, j], color="C0", alpha=0.2,
                                label=f"±{n_sigma:g}σ")
        axes[1, j].set(xlabel="t [s]", ylabel=f"error {name} [cm]")
    axes[0, 0].legend(fontsize=8)
    axes[1, 0].legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_observability_spectrum(singular_values: Mapping[str, ArrayLike], n_unobservable: int = 4,
                                title: str = "") -> "Figure":
    """Return the singular values of observability matrices, smallest first, each divided by its largest (log scale).

    Args:
        singular_values: label -> (n,) singular values of one observability matrix (any order, >= 0), e.g. the
            15 of the IMU error state built with different linearisation points.
        n_unobservable: the number of directions the true system cannot observe (4 for visual-inertial odometry:
            global position and yaw); a dotted line separates them from the rest.
        title: figure title.

    A direction is unobservable when its singular value is zero; numerically, when it lies many orders of magnitude
    below the others (round-off is about 1e-16 of the largest). One marker style per matrix.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_observability_spectrum({"ideal": [1e-16, 1e-15, 1e-16, 1e-15, 0.1, 1.0]}, n_unobservable=4)
    >>> [float(x) for x in fig.axes[0].lines[0].get_ydata()][:2]
    [1e-16, 1e-16]
    """
    import matplotlib.pyplot as plt

    if not isinstance(singular_values, Mapping) or not singular_values:
        raise ValueError(f"singular_values must be a non-empty mapping label -> (n,) array; "
                         f"got {type(singular_values).__name__}")
    if isinstance(n_unobservable, bool) or not isinstance(n_unobservable, (int, np.integer)) or n_unobservable < 0:
        raise ValueError(f"n_unobservable must be an integer >= 0; got {n_unobservable!r}")
    spectra = {}
    for label, value in singular_values.items():
        sv = np.asarray(value, dtype=np.float64)
        if sv.ndim != 1 or sv.size == 0 or np.any(sv < 0) or not np.all(np.isfinite(sv)) or sv.max() <= 0:
            raise ValueError(f"singular_values[{label!r}] must be a (n,) array of finite values >= 0, not all zero; "
                             f"got shape {sv.shape}")
        spectra[label] = np.sort(sv) / sv.max()
    floor = 1e-17
    fig, ax = plt.subplots(figsize=(7, 3.8))
    markers = ("o", "s", "^", "D", "v")
    for k, (label, sv) in enumerate(spectra.items()):
        index = np.arange(1, sv.size + 1)
        ax.semilogy(index, np.maximum(sv, floor), marker=markers[k % len(markers)], ls="-", lw=0.8,
                    color=f"C{k}", label=label, alpha=0.85)
    if n_unobservable:
        ax.axvline(n_unobservable + 0.5, color="0.3", ls=":", lw=1.0,
                   label=f"{n_unobservable} unobservable directions | the rest")
    size = max(sv.size for sv in spectra.values())
    ax.set_xticks(np.arange(1, size + 1))
    ax.set(xlabel="singular value index (smallest first)", ylabel="singular value / largest (dimensionless)",
           title=title or "singular values of the observability matrix")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------------------------------- schematics
_SCHEMATIC_STATE = "#d9f0d3"  # the palette of evio_lib.evaluation.plots_schematics: a state
_SCHEMATIC_SENSOR = "#dbe9f6"  # sensor data


def _blank(ax: "Axes", width: float, height: float, title: str) -> None:
    """Make ``ax`` a drawing board of width x height units with a title and no axes."""
    ax.set_xlim(0.0, width)
    ax.set_ylim(0.0, height)
    ax.set_aspect("equal")
    ax.set_axis_off()
    ax.set_title(title, fontsize=10)


def _camera_glyph(ax: "Axes", x: float, y: float, towards: Sequence[float], size: float = 0.32,
                  colour: str = _SCHEMATIC_SENSOR) -> None:
    """Draw a small camera (a triangle, apex at the centre, opening towards the point ``towards``)."""
    from matplotlib.patches import Polygon

    d = np.asarray(towards, dtype=np.float64) - (x, y)
    d /= max(np.linalg.norm(d), 1e-9)
    n = np.array([-d[1], d[0]])
    apex = np.array([x, y])
    base = apex + size * d
    ax.add_patch(Polygon([apex, base + 0.6 * size * n, base - 0.6 * size * n], closed=True, facecolor=colour,
                         edgecolor="0.25", lw=1.0, zorder=3))


def plot_feature_update_schematic(num_clones: int = 5) -> "Figure":
    """Return the MSCKF update of one feature in three panels (thesis §3.3.6-3.3.7, Eqs. 41-58).

    (a) A feature seen from several camera clones of the sliding window; its position is not in the state and is
    triangulated from the clones' poses. (b) In one image, the measured point z_i, the prediction ẑ_i from the
    triangulated feature and the clone's pose, the residual r_i = z_i - ẑ_i and its noise ellipse Σ_i (stretched
    by the lens's undistortion); whitening by W_i = L_i^-1 (Σ_i = L_i L_i^T) makes the noise a unit circle.
    (c) The stacked whitened residual r (2M rows) split in the residual space: the part an error of the feature
    can explain (the column space of H_f, 3 dimensions, dropped) and the part orthogonal to it, r_o = A^T r with
    A^T H_f = 0 (2M - 3 rows, kept: it depends on the clones' errors only).

    Args:
        num_clones: camera clones observing the feature in panel (a), >= 2.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_feature_update_schematic()
    >>> [ax.get_title().split(")")[0] for ax in fig.axes]
    ['(a', '(b', '(c']
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Ellipse, FancyArrowPatch, Rectangle

    if isinstance(num_clones, bool) or not isinstance(num_clones, (int, np.integer)) or num_clones < 2:
        raise ValueError(f"num_clones must be an integer >= 2; got {num_clones!r}")
    fig, axes = plt.subplots(1, 3, figsize=(14.5, 4.8), gridspec_kw={"width_ratios": [1.0, 1.15, 1.0]})

    # (a) one feature, several clones
    ax = axes[0]
    _blank(ax, 5.0, 5.0, "(a) one feature, seen from M camera clones")
    feature = np.array([2.6, 4.1])
    s = np.linspace(0.0, 1.0, int(num_clones))
    path = np.column_stack([0.5 + 3.8 * s, 0.9 + 0.9 * np.sin(np.pi * s) - 0.3 * s])
    ax.plot(path[:, 0], path[:, 1], color="0.6", lw=1.0, ls="-")
    for i, (x, y) in enumerate(path):
        ax.plot([x, feature[0]], [y, feature[1]], color="goldenrod", lw=1.0, ls="--", zorder=1)
        _camera_glyph(ax, x, y, feature)
        ax.text(x, y - 0.28, f"C{i + 1}", ha="center", va="top", fontsize=8)
    ax.plot(*feature, marker="*", ms=16, color="goldenrod", zorder=4)
    ax.text(feature[0] + 0.2, feature[1] + 0.05, "feature p_f\n(not in the state)", fontsize=8, va="bottom")
    ax.text(2.5, 0.05, "clone poses (q_GtoCi, p_CiinG) are in the state;\np_f is triangulated from them",
            ha="center", va="bottom", fontsize=8, color="0.25")

    # (b) the residual in one image, and whitening
    ax = axes[1]
    _blank(ax, 6.0, 5.0, "(b) residual in image i, whitened per observation")
    ax.add_patch(Rectangle((0.2, 1.0), 3.0, 3.0, facecolor="white", edgecolor="0.3", lw=1.0))
    ax.text(1.7, 4.1, "image i (normalised coordinates)", ha="center", va="bottom", fontsize=8)
    z, z_hat = np.array([2.05, 2.75]), np.array([1.35, 2.1])
    ax.add_patch(Ellipse(z, 1.3, 0.55, angle=35.0, facecolor="C0", alpha=0.18, edgecolor="C0"))
    ax.plot(*z, "o", color="C0", ms=6)
    ax.text(z[0] + 0.12, z[1] + 0.1, "z_i measured", fontsize=8, color="C0")
    ax.plot(*z_hat, "x", color="C3", ms=8, mew=2)
    ax.text(z_hat[0] - 0.1, z_hat[1] - 0.2, "ẑ_i = h(clone i, p_f)", fontsize=8, color="C3", ha="center", va="top")
    ax.add_patch(FancyArrowPatch(tuple(z_hat), tuple(z), arrowstyle="-|>", mutation_scale=12, color="k", lw=1.3))
    ax.text(1.45, 2.55, "r_i", fontsize=9)
    ax.text(z[0] - 0.3, 1.25, "noise Σ_i\n(stretched by\nundistortion)", fontsize=7.5, color="C0", ha="center")
    ax.add_patch(FancyArrowPatch((3.35, 2.5), (4.35, 2.5), arrowstyle="-|>", mutation_scale=14, color="0.2"))
    ax.text(3.85, 2.65, "W_i = L_i⁻¹", ha="center", va="bottom", fontsize=8.5)
    ax.text(3.85, 2.3, "Σ_i = L_i L_iᵀ", ha="center", va="top", fontsize=7.5, color="0.3")
    ax.add_patch(Ellipse((5.15, 2.5), 0.8, 0.8, facecolor="C0", alpha=0.18, edgecolor="C0"))
    ax.plot(5.15, 2.5, "o", color="C0", ms=5)
    ax.text(5.15, 1.9, "W_i r_i: unit noise,\nthe same for every row", ha="center", va="top", fontsize=7.5)
    ax.text(3.0, 0.25, "rows 2i, 2i+1 of r, H_x and H_f are multiplied by W_i", ha="center", fontsize=8,
            color="0.25")

    # (c) the nullspace projection
    ax = axes[2]
    _blank(ax, 5.0, 5.0, "(c) project out the feature: r_o = Aᵀ r")
    origin = np.array([0.6, 1.0])
    direction = np.array([0.95, 0.32])
    direction /= np.linalg.norm(direction)
    ax.plot(*np.column_stack([origin - 0.4 * direction, origin + 4.3 * direction]), color="0.45", lw=2.0)
    ax.text(*(origin + 4.0 * direction + [-0.3, -0.35]), "span H_f: what an\nerror of p_f explains", fontsize=8,
            color="0.35", ha="center", va="top")
    r_end = origin + np.array([2.6, 3.0])
    along = origin + np.dot(r_end - origin, direction) * direction
    ax.add_patch(FancyArrowPatch(tuple(origin), tuple(r_end), arrowstyle="-|>", mutation_scale=13, color="k",
                                 lw=1.4))
    ax.text(*(0.5 * (origin + r_end) + [-0.35, 0.1]), "r (whitened,\n2M rows)", fontsize=8, ha="center")
    ax.add_patch(FancyArrowPatch(tuple(origin), tuple(along), arrowstyle="-|>", mutation_scale=12, color="C3",
                                 lw=1.6, linestyle="--", zorder=3))
    ax.text(*(0.5 * (origin + along) + [0.25, -0.3]), "dropped", fontsize=8, color="C3", ha="center", va="top")
    ax.add_patch(FancyArrowPatch(tuple(along), tuple(r_end), arrowstyle="-|>", mutation_scale=13, color="C2",
                                 lw=2.0))
    ax.text(*(0.5 * (along + r_end) + [0.15, 0.0]), "r_o = Aᵀ r\nkept: 2M − 3 rows,\nclones' errors only",
            fontsize=8, color="C2", va="center")
    ax.text(2.5, 0.05, "Aᵀ H_f = 0, Aᵀ A = I: the feature's error drops out,\nthe whitened noise stays unit",
            ha="center", va="bottom", fontsize=8, color="0.25")
    fig.tight_layout()
    return fig


def plot_unobservable_directions_schematic() -> "Figure":
    """Return the four unobservable directions of visual-inertial odometry, and an observable one (thesis §3.3.8).

    (a) Shifting the whole world (trajectory and landmarks) by any vector changes no image and no IMU sample: the
    global position (3 directions) is unobservable. (b) Turning the whole world about the gravity axis (yaw) keeps
    gravity where it was: no sensor tells, 1 direction. (c) Tilting it (roll or pitch) turns gravity relative to the
    body, which the accelerometer feels: observable. Together: the 4 columns of N (Eq. 80), and 15 - 4 = 11
    observable directions of the IMU error state.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_unobservable_directions_schematic()
    >>> [ax.get_title().split(")")[0] for ax in fig.axes]
    ['(a', '(b', '(c']
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Arc, FancyArrowPatch

    fig, axes = plt.subplots(1, 3, figsize=(14.5, 4.8))
    s = np.linspace(0.0, 1.0, 60)
    path = np.column_stack([0.5 + 2.2 * s, 1.9 + 0.45 * np.sin(2.2 * np.pi * s) + 0.4 * s])
    landmarks = np.array([[0.8, 3.6], [1.7, 3.95], [2.6, 3.5], [3.0, 2.7]])
    poses = path[[0, 30, 59]]
    centre = np.array([1.7, 2.8])

    def world(ax, offset=(0.0, 0.0), angle=0.0, colour="k", style="-"):
        c, sn = np.cos(angle), np.sin(angle)
        R = np.array([[c, -sn], [sn, c]])
        move = lambda pts: (pts - centre) @ R.T + centre + offset  # noqa: E731
        p = move(path)
        ax.plot(p[:, 0], p[:, 1], color=colour, ls=style, lw=1.4)
        lm = move(landmarks)
        ax.plot(lm[:, 0], lm[:, 1], "s", color=colour, ms=6, mfc="none" if style != "-" else colour)
        for q in move(poses):
            ax.plot([q[0], lm[1, 0]], [q[1], lm[1, 1]], color=colour, lw=0.6, ls=":", alpha=0.7)
            ax.plot(*q, "o", color=colour, ms=4)

    # (a) translation
    ax = axes[0]
    _blank(ax, 5.5, 5.0, "(a) shift everything: unobservable (3)")
    world(ax)
    shift = np.array([1.9, -0.55])
    world(ax, offset=shift, colour="C0", style="--")
    ax.add_patch(FancyArrowPatch(tuple(landmarks[3]), tuple(landmarks[3] + shift), arrowstyle="-|>",
                                 mutation_scale=14, color="C0", lw=1.5))
    ax.text(*(landmarks[3] + 0.5 * shift + [0.1, 0.12]), "δp", color="C0", fontsize=10)
    ax.text(2.75, 0.2, "trajectory (line, dots: camera poses) and landmarks\n(squares) moved together: the same "
            "images and\nIMU samples. Global position δp (x, y, z)", ha="center", fontsize=8)

    # (b) yaw about gravity, seen from above
    ax = axes[1]
    _blank(ax, 5.5, 5.0, "(b) turn everything about gravity: unobservable (1)")
    yaw = np.radians(35.0)
    world(ax)
    world(ax, angle=yaw, colour="C0", style="--")
    ax.add_patch(Arc(tuple(centre), 3.0, 3.0, theta1=-20.0, theta2=-20.0 + np.degrees(yaw), color="C0", lw=1.5))
    ax.plot(*centre, "o", ms=12, mfc="white", mec="0.2")
    ax.plot(*centre, ".", ms=5, color="0.2")
    ax.text(centre[0] + 1.0, centre[1] - 1.0, "yaw ψ", color="C0", fontsize=10)
    ax.text(centre[0] - 0.25, centre[1] - 0.25, "g", ha="right", va="top", fontsize=9)
    ax.text(2.75, 0.2, "seen from above, gravity out of the page: turned\nabout g, gravity is unchanged; the same "
            "images and\nIMU samples. Yaw ψ about g", ha="center", fontsize=8)

    # (c) tilt: observable
    ax = axes[2]
    _blank(ax, 5.5, 5.0, "(c) tilt (roll, pitch): observable")
    for angle, colour, style, label in ((0.0, "k", "-", "level"), (np.radians(25.0), "C3", "--", "tilted")):
        c, sn = np.cos(angle), np.sin(angle)
        body = np.array([[-0.7, -0.25], [0.7, -0.25], [0.7, 0.25], [-0.7, 0.25], [-0.7, -0.25]])
        mid = np.array([1.6, 2.8]) if angle == 0 else np.array([3.9, 2.8])
        pts = body @ np.array([[c, -sn], [sn, c]]).T + mid
        ax.plot(pts[:, 0], pts[:, 1], color=colour, ls=style, lw=1.5)
        up = np.array([-sn, c])
        ax.add_patch(FancyArrowPatch(tuple(mid), tuple(mid + 0.9 * up), arrowstyle="-|>", mutation_scale=11,
                                     color=colour, lw=1.2))
        ax.text(*(mid + 1.05 * up), "body z", color=colour, fontsize=8.5, ha="center")
        ax.add_patch(FancyArrowPatch(tuple(mid - [0.0, 0.4]), tuple(mid - [0.0, 1.5]), arrowstyle="-|>",
                                     mutation_scale=13, color="0.2", lw=1.5))
        ax.text(mid[0] + 0.1, mid[1] - 1.2, "g", fontsize=10)
        ax.text(mid[0], mid[1] - 1.75, label, ha="center", va="top", fontsize=8, color=colour)
    ax.text(2.75, 0.2, "side view: tilted, the body feels gravity at\nanother angle (the accelerometer measures "
            "it):\nroll and pitch are observable", ha="center", fontsize=8)
    fig.tight_layout()
    return fig
