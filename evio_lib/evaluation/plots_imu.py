"""Figures for the IMU lesson (notebook 09): attitude, velocity and position error of IMU-only propagation.

Plotting only; the integration lives in :mod:`evio_lib.msckf.propagation`. Matplotlib is imported when a figure is made.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Mapping

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["plot_pose_errors"]

_PANELS = ("attitude error [deg]", "velocity error [m/s]", "position error [m]")


def plot_pose_errors(t: ArrayLike, errors: Mapping[str, tuple[ArrayLike, ArrayLike, ArrayLike]],
                     title: str = "", log: bool = True) -> "Figure":
    """Return a figure of three panels (attitude, velocity, position error against time), one line per run.

    Args:
        t: (T,) times [s].
        errors: label -> (attitude error [deg], velocity error [m/s], position error [m]), each (T,) and >= 0.
        title: figure title.
        log: logarithmic y axes (the first sample, often exactly 0, is then left out).

    >>> import matplotlib; matplotlib.use("Agg")
    >>> e = np.array([0.0, 0.1, 0.4])
    >>> fig = plot_pose_errors([0.0, 1.0, 2.0], {"run": (e, e, e)})
    >>> len(fig.axes), len(fig.axes[0].lines)
    (3, 1)
    """
    import matplotlib.pyplot as plt

    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1 or t.shape[0] < 2 or not np.all(np.isfinite(t)):
        raise ValueError(f"t must be a finite array of shape (T,), T >= 2; got shape {t.shape}")
    if not isinstance(errors, Mapping) or not errors:
        raise ValueError(f"errors must be a non-empty mapping label -> (attitude, velocity, position); "
                         f"got {type(errors).__name__}")
    curves = {}
    for label, value in errors.items():
        if len(value) != 3:
            raise ValueError(f"errors[{label!r}] must be (attitude, velocity, position) arrays; got {len(value)} items")
        arrays = [np.asarray(v, dtype=np.float64) for v in value]
        for name, a in zip(_PANELS, arrays):
            if a.shape != t.shape:
                raise ValueError(f"errors[{label!r}] {name} must have shape (T,) = {t.shape} like t; got {a.shape}")
        curves[label] = arrays
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.6))
    first = 1 if log else 0
    for label, arrays in curves.items():
        for ax, y in zip(axes, arrays):
            (ax.semilogy if log else ax.plot)(t[first:], y[first:], label=label)
    for ax, name in zip(axes, _PANELS):
        ax.set_xlabel("time [s]")
        ax.set_ylabel(name)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig
