"""Figures for the MSCKF lessons (notebooks 09-12): error growth, Monte-Carlo errors against 3-sigma bounds, covariance,
triangulation error against the number of views, NEES against its chi-square band, a filter run against the truth.

Plotting only (plus :func:`correlation_matrix`, the normalised covariance the structure plot shows); the filter lives
in :mod:`evio_lib.msckf`. Matplotlib is imported when a figure is made.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:  # pragma: no cover
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
                             title: str = "") -> "Figure":
    """Return the median triangulation error [cm] against the number of views, one line per pixel-noise level.

    Args:
        view_counts: (V,) numbers of views M of the track (x axis).
        median_error: (L, V) median position error of the triangulated feature [m], row l for noise level l.
        noise_levels_px: (L,) standard deviation of the pixel noise of each row [px] (the legend).
        title: figure title.

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
    fig, ax = plt.subplots(figsize=(6, 3.5))
    for noise_px, row in zip(noise, errors):
        ax.plot(views, 100 * row, "o-", label=f"{noise_px:g} px noise")  # m -> cm
    ax.set(xlabel="number of views (same time span)", ylabel="median position error [cm]", title=title)
    ax.legend()
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
