"""Figures for the IMU lesson (notebook 09).

- :func:`plot_imu_model_schematic`: the IMU model drawn: a tilted, accelerating body with gravity and the specific
  force its accelerometer feels, and the measurement model (gyroscope and accelerometer, each with a random-walk
  bias and white noise) feeding the integration into attitude, velocity and position (thesis Eq. 31).
- :func:`plot_pose_errors`: attitude, velocity and position error of IMU-only propagation against time.

Plotting only; the integration lives in :mod:`evio_lib.msckf.propagation` and the sensor model in
:mod:`evio_lib.sim.imu`. Matplotlib is imported when a figure is made.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from evio_lib.sim.imu import GRAVITY_G

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["specific_force_in_body", "plot_imu_model_schematic", "plot_pose_errors"]

_PANELS = ("attitude error [deg]", "velocity error [m/s]", "position error [m]")


_SENSOR, _PROCESS, _STATE, _ERROR = "#dbe9f6", "#fde9c9", "#d9f0d3", "#f7d4d0"


def specific_force_in_body(tilt_deg: float, accel_G: Sequence[float]) -> np.ndarray:
    """Return the specific force (x_I, z_I) [m/s²] a body pitched by ``tilt_deg`` feels while accelerating.

    The motion lies in the x_G-z_G plane (z_G up, gravity ``GRAVITY_G``); the body's x axis is turned ``tilt_deg``
    up from x_G. The accelerometer reads ``R_GtoI (a - g)``, so at rest (a = 0) it reads +9.81 m/s² along "up".

    Args:
        tilt_deg: pitch of the body [deg].
        accel_G: the body's acceleration (a_x, a_z) in G [m/s²].

    >>> specific_force_in_body(0.0, (0.0, 0.0))   # level and at rest: 1 g up
    array([0.  , 9.81])
    """
    a = np.asarray(accel_G, dtype=np.float64)
    if a.shape != (2,) or not np.all(np.isfinite(a)) or not np.isfinite(tilt_deg):
        raise ValueError(f"accel_G must be a finite (a_x, a_z) pair [m/s²] and tilt_deg finite; got {accel_G!r}, "
                         f"{tilt_deg!r}")
    theta = np.radians(tilt_deg)
    x_I = np.array([np.cos(theta), np.sin(theta)])
    z_I = np.array([-np.sin(theta), np.cos(theta)])
    f_G = a - GRAVITY_G[[0, 2]]
    return np.array([f_G @ x_I, f_G @ z_I])


def _box(ax: "Axes", x: float, y: float, w: float, h: float, text: str, colour: str,
         fontsize: float = 9.0) -> tuple[float, float, float, float]:
    from matplotlib.patches import FancyBboxPatch

    ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0.02,rounding_size=0.08", facecolor=colour,
                                edgecolor="0.25", linewidth=1.0))
    ax.text(x + w / 2, y + h / 2, text, ha="center", va="center", fontsize=fontsize)
    return x, y, w, h


def _node(ax: "Axes", x: float, y: float, sign: str) -> tuple[float, float, float, float]:
    from matplotlib.patches import Circle

    ax.add_patch(Circle((x, y), 0.26, facecolor="white", edgecolor="0.25", linewidth=1.0))
    ax.text(x, y, sign, ha="center", va="center", fontsize=11)
    return x - 0.26, y - 0.26, 0.52, 0.52


def _link(ax: "Axes", start: Sequence[float], end: Sequence[float], text: str = "", colour: str = "0.2",
          offset: Sequence[float] = (0.0, 0.1), **text_options) -> None:
    ax.annotate("", xy=tuple(end), xytext=tuple(start),
                arrowprops=dict(arrowstyle="-|>", color=colour, lw=1.3, shrinkA=1, shrinkB=1))
    if text:
        options = dict(ha="center", va="bottom", fontsize=8.5, color=colour)
        options.update(text_options)
        ax.text(0.5 * (start[0] + end[0]) + offset[0], 0.5 * (start[1] + end[1]) + offset[1], text, **options)


def _side(box: tuple[float, float, float, float], where: str) -> tuple[float, float]:
    x, y, w, h = box
    return {"left": (x, y + h / 2), "right": (x + w, y + h / 2), "top": (x + w / 2, y + h),
            "bottom": (x + w / 2, y)}[where]


def plot_imu_model_schematic(tilt_deg: float = 20.0, accel_G: Sequence[float] = (4.0, 0.0)) -> "Figure":
    """Return the IMU model drawn: the specific force on a body (left) and measurement plus integration (right).

    Left, to scale in m/s²: a body pitched by ``tilt_deg`` accelerating by ``accel_G`` in the x_G-z_G plane, its axes
    x_I and z_I, gravity g, the acceleration a and the specific force f = a - g the accelerometer feels (the
    parallelogram a + (-g)); the legend gives f in the body frame (:func:`specific_force_in_body`).
    Right: the measurement model of the thesis's IMU (§3.3.4): the gyroscope reads the true rate plus a bias
    (a random walk) and white noise, the accelerometer the specific force plus its own bias and noise; dead reckoning
    subtracts the estimated biases and integrates thesis Eq. 31 into attitude, velocity and position.

    Args:
        tilt_deg: pitch of the drawn body [deg], within ±60.
        accel_G: the body's acceleration (a_x, a_z) in G [m/s²], each within ±8.

    >>> import matplotlib; matplotlib.use("Agg")
    >>> fig = plot_imu_model_schematic()
    >>> len(fig.axes)
    2
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon

    a = np.asarray(accel_G, dtype=np.float64)
    if not (np.isfinite(tilt_deg) and abs(tilt_deg) <= 60.0):
        raise ValueError(f"tilt_deg must be a pitch within ±60 degrees; got {tilt_deg!r}")
    if a.shape != (2,) or not np.all(np.isfinite(a)) or np.abs(a).max() > 8.0:
        raise ValueError(f"accel_G must be an (a_x, a_z) pair within ±8 m/s² each; got {accel_G!r}")
    f_I = specific_force_in_body(tilt_deg, a)
    theta = np.radians(tilt_deg)
    x_I = np.array([np.cos(theta), np.sin(theta)])
    z_I = np.array([-np.sin(theta), np.cos(theta)])
    minus_g = -GRAVITY_G[[0, 2]]
    f_G = a + minus_g

    fig = plt.figure(figsize=(15.0, 5.4))
    grid = fig.add_gridspec(1, 2, width_ratios=(0.62, 1.6))
    ax = fig.add_subplot(grid[0])
    body = np.array([[-2.2, -1.1], [2.2, -1.1], [2.2, 1.1], [-2.2, 1.1]])
    ax.add_patch(Polygon(body @ np.column_stack([x_I, z_I]).T, closed=True, facecolor="0.88", edgecolor="0.3"))
    for axis, name in ((x_I, "x_I"), (z_I, "z_I")):
        ax.annotate("", xy=tuple(3.2 * axis), xytext=(0, 0), arrowprops=dict(arrowstyle="-|>", color="0.35", lw=1.2))
        ax.text(*(3.7 * axis + [0.0, 0.35]), name, color="0.35", fontsize=9, ha="center", va="center")
    vectors = ((a, "tab:green", "a: acceleration"), (minus_g, "0.5", "−g"), (f_G, "tab:orange", "f = a − g"))
    for vector, colour, label in vectors:
        ax.annotate("", xy=tuple(vector), xytext=(0, 0), arrowprops=dict(arrowstyle="-|>", color=colour, lw=2.2))
        ax.text(*(vector + [0.3, 0.4]), label, color=colour, fontsize=9.5)
    ax.plot([a[0], f_G[0], minus_g[0]], [a[1], f_G[1], minus_g[1]], ":", color="0.5", lw=1)
    ax.annotate("", xy=(-4.5, -9.0), xytext=(-4.5, 0.81), arrowprops=dict(arrowstyle="-|>", color="tab:blue", lw=2.2))
    ax.text(-4.3, -5.0, "gravity g\n9.81 m/s²", color="tab:blue", fontsize=9)
    ax.set(xlim=(-6.0, 9.0), ylim=(-10.0, 12.5), aspect="equal", xlabel="x_G [m/s²]", ylabel="z_G (up) [m/s²]")
    ax.grid(alpha=0.3)
    ax.set_title(f"specific force: body pitched {tilt_deg:g}°, accelerating {np.linalg.norm(a):g} m/s²\n"
                 f"the accelerometer reads f in I: ({f_I[0]:.2f}, {f_I[1]:.2f}) m/s² along (x_I, z_I)", fontsize=9.5)

    ax2 = fig.add_subplot(grid[1])
    ax2.set_xlim(0.0, 15.4)
    ax2.set_ylim(0.0, 7.8)
    ax2.set_aspect("equal")
    ax2.set_axis_off()
    ax2.set_title("the IMU model (thesis §3.3.4) and dead reckoning (Eq. 31)", fontsize=10)
    top, bottom, h = 4.6, 1.5, 1.1
    gyro_true = _box(ax2, 0.1, top, 2.2, h, "true angular rate\n" r"$\boldsymbol{\omega}_I$", _STATE)
    accel_true = _box(ax2, 0.1, bottom, 2.2, h, "true specific force\n" r"$R_{GtoI}(\mathbf{a} - \mathbf{g}_G)$",
                      _STATE)
    plus_g, plus_a = _node(ax2, 2.95, top + h / 2, "+"), _node(ax2, 2.95, bottom + h / 2, "+")
    for y, name in ((top + 1.65, "g"), (bottom - 1.5, "a")):
        text = rf"bias $\mathbf{{b}}_{name}$: random walk" "\n" rf"+ white noise $\mathbf{{n}}_{name}$"
        _box(ax2, 1.6, y, 2.7, 0.95, text, _ERROR, 8.5)
    gyro = _box(ax2, 3.6, top, 1.9, h, "gyroscope\n" r"$\boldsymbol{\omega}_m$", _SENSOR)
    accel = _box(ax2, 3.6, bottom, 1.9, h, "accelerometer\n" r"$\mathbf{a}_m$", _SENSOR)
    _link(ax2, _side(gyro_true, "right"), _side(plus_g, "left"))
    _link(ax2, _side(accel_true, "right"), _side(plus_a, "left"))
    _link(ax2, (2.95, top + 1.65), _side(plus_g, "top"))
    _link(ax2, (2.95, bottom - 0.55), _side(plus_a, "bottom"))
    _link(ax2, _side(plus_g, "right"), _side(gyro, "left"))
    _link(ax2, _side(plus_a, "right"), _side(accel, "left"))
    ax2.plot([5.95, 5.95], [0.1, 7.4], ls="--", color="0.55", lw=1)
    ax2.text(3.0, 7.45, "what the IMU measures", ha="center", fontsize=9, style="italic")
    ax2.text(10.6, 7.45, "what dead reckoning computes", ha="center", fontsize=9, style="italic")
    minus_g_node, minus_a_node = _node(ax2, 6.5, top + h / 2, "−"), _node(ax2, 6.5, bottom + h / 2, "−")
    _box(ax2, 5.55, top + 1.65, 1.9, 0.75, r"estimate $\hat{\mathbf{b}}_g$", _ERROR, 8.5)
    _box(ax2, 5.55, bottom - 1.3, 1.9, 0.75, r"estimate $\hat{\mathbf{b}}_a$", _ERROR, 8.5)
    _link(ax2, _side(gyro, "right"), _side(minus_g_node, "left"))
    _link(ax2, _side(accel, "right"), _side(minus_a_node, "left"))
    _link(ax2, (6.5, top + 1.65), _side(minus_g_node, "top"))
    _link(ax2, (6.5, bottom - 0.55), _side(minus_a_node, "bottom"))
    q_dot = _box(ax2, 7.25, top, 2.6, h, r"$\dot{\bar q} = \frac{1}{2}\,\Omega(\boldsymbol{\omega})\,\bar q$",
                 _PROCESS, 10)
    v_dot = _box(ax2, 7.25, bottom, 2.6, h, r"$\dot{\mathbf{v}} = R_{ItoG}\,\mathbf{a} + \mathbf{g}_G$",
                 _PROCESS, 10)
    _link(ax2, _side(minus_g_node, "right"), _side(q_dot, "left"), r"$\boldsymbol{\omega}$", offset=(0.0, 0.05))
    _link(ax2, _side(minus_a_node, "right"), _side(v_dot, "left"), r"$\mathbf{a}$", offset=(0.0, 0.05))
    attitude = _box(ax2, 10.6, top, 2.1, h, "attitude\n" r"$\bar q_{GtoI}$", _STATE)
    velocity = _box(ax2, 10.6, bottom, 2.1, h, "velocity\n" r"$\mathbf{v}_{IinG}$", _STATE)
    position = _box(ax2, 13.25, bottom, 2.1, h, "position\n" r"$\mathbf{p}_{IinG}$", _STATE)
    _link(ax2, _side(q_dot, "right"), _side(attitude, "left"), "∫ dt")
    _link(ax2, _side(v_dot, "right"), _side(velocity, "left"), "∫ dt")
    _link(ax2, _side(velocity, "right"), _side(position, "left"), "∫ dt")
    _link(ax2, (11.0, top), (9.3, bottom + h), "$R_{ItoG}$: rotate a into G", offset=(0.85, 0.0), ha="left",
          va="center")
    _box(ax2, 7.45, 0.05, 2.2, 0.7, r"gravity $\mathbf{g}_G$ (known)", _SENSOR, 8.5)
    _link(ax2, (8.55, 0.75), _side(v_dot, "bottom"))
    fig.tight_layout()
    return fig


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
