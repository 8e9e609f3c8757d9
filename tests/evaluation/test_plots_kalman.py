"""Tests of evio_lib.evaluation.plots_kalman: the figures render to Agg, draw what they are given, label their axes
with units, and reject bad input with a clear message."""
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from evio_lib.evaluation.plots_kalman import (  # noqa: E402
    gaussian_product,
    plot_attitude_filter_run,
    plot_gate,
    plot_kalman_cycle_schematic,
    plot_nees_nis,
    plot_track_1d,
)


def test_gaussian_product_is_the_scalar_kalman_update():
    mean, var = gaussian_product(2.0, 0.25, 2.6, 0.16)
    gain = 0.25 / (0.25 + 0.16)
    assert mean == pytest.approx(2.0 + gain * 0.6) and var == pytest.approx((1 - gain) * 0.25)
    assert var < min(0.25, 0.16) and 2.0 < mean < 2.6  # between the two, narrower than either
    with pytest.raises(ValueError, match="variances must be > 0"):
        gaussian_product(0.0, 0.0, 1.0, 1.0)


def test_schematic_draws_the_cycle_and_the_four_densities():
    fig = plot_kalman_cycle_schematic(x_prev=1.0, var_prev=0.09, velocity=2.0, dt=0.5, q=0.16, z=2.6, var_z=0.16)
    cycle, densities = fig.axes
    texts = " ".join(t.get_text() for t in cycle.texts)
    assert not cycle.axison and "predict" in texts and "update" in texts and "K = P Hᵀ S⁻¹" in texts
    assert (densities.get_xlabel(), densities.get_ylabel()) == ("position [m]", "probability density [1/m]")
    labels = [line.get_label() for line in densities.lines]
    assert len(labels) == 4 and labels[1].startswith("prior at k") and "N(2.00, 0.25)" in labels[1]
    mean, var = gaussian_product(2.0, 0.25, 2.6, 0.16)
    assert f"N({mean:.2f}, {var:.3f})" in labels[3]
    peak = densities.lines[3].get_xdata()[np.argmax(densities.lines[3].get_ydata())]
    assert peak == pytest.approx(mean, abs=0.02)  # the posterior is drawn where the product says
    assert "K = P̄ / (P̄ + R) = 0.61" in densities.get_title()
    fig.canvas.draw()
    with pytest.raises(ValueError, match="var_prev, var_z, dt > 0"):
        plot_kalman_cycle_schematic(var_z=0.0)


def test_track_figure_draws_truth_measurements_estimate_and_band():
    t = np.linspace(0.1, 2.0, 20)
    truth = np.c_[t, np.ones(20)]
    fig = plot_track_1d(t, truth, t + 0.1, truth + 0.05, np.full((20, 2), 0.2), title="demo")
    pos, vel = fig.axes
    assert (pos.get_ylabel(), vel.get_ylabel(), vel.get_xlabel()) == ("position [m]", "velocity [m/s]", "time [s]")
    assert [line.get_label() for line in pos.lines] == ["truth", "measurements z", "filter estimate"]
    assert [line.get_label() for line in vel.lines] == ["truth", "filter estimate"]
    band = pos.collections[0].get_paths()[0].vertices[:, 1]
    assert band.min() == pytest.approx(0.15 - 0.4) and band.max() == pytest.approx(2.05 + 0.4)  # ±2σ
    fig.canvas.draw()
    with pytest.raises(ValueError, match=r"estimate must be a finite array of shape \(T, 2\) = \(20, 2\)"):
        plot_track_1d(t, truth, t, truth[:5], np.ones((20, 2)))
    with pytest.raises(ValueError, match=r"measurements must be a finite array of shape \(T,\) = \(20,\)"):
        plot_track_1d(t, truth, t[:3], truth, np.ones((20, 2)))


def test_nees_nis_figure_has_one_curve_per_filter_and_the_bands():
    t = np.linspace(0.1, 1.0, 10)
    nees = {"right Q": np.full(10, 2.0), "Q too small": np.full(10, 9.0)}
    nis = {"right Q": np.full(10, 1.0), "Q too small": np.full(10, 1.2)}
    fig = plot_nees_nis(t, nees, nis, (1.6, 2.5), (0.7, 1.3), nees_dof=2, nis_dof=1, n_runs=50)
    left, right = fig.axes
    assert left.get_yscale() == "log" and right.get_yscale() == "linear"
    assert [line.get_label() for line in left.lines][1:] == ["right Q", "Q too small"]
    assert left.lines[0].get_ydata()[0] == 2 and right.lines[0].get_ydata()[0] == 1  # expected values
    assert "95 % χ² interval (50 runs)" in [text.get_text() for text in fig.legends[0].get_texts()]
    assert left.get_ylabel() == "average NEES (dimensionless)" and left.get_xlabel() == "time [s]"
    fig.canvas.draw()
    assert fig._suptitle is None  # no title unless asked for
    titled = plot_nees_nis(t, nees, nis, (1.6, 2.5), (0.7, 1.3), 2, 1, 50, title="two filters")
    assert titled._suptitle.get_text() == "two filters"
    titled.canvas.draw()
    tick_text = [label.get_text() for label in titled.axes[0].get_yticklabels(minor=True)
                 + titled.axes[0].get_yticklabels()]
    assert not any("times" in text or "^" in text for text in tick_text)  # plain numbers on the log axis
    assert titled._suptitle.get_window_extent().y0 >= max(ax.title.get_window_extent().y1 for ax in titled.axes) - 1
    with pytest.raises(ValueError, match="the same labels"):
        plot_nees_nis(t, nees, {"right Q": nis["right Q"]}, (1.6, 2.5), (0.7, 1.3), 2, 1, 50)
    with pytest.raises(ValueError, match="nees_band must satisfy 0 <= lo < hi"):
        plot_nees_nis(t, nees, nis, (3.0, 2.5), (0.7, 1.3), 2, 1, 50)


def test_gate_figure_marks_the_threshold_and_the_outlier():
    t = np.linspace(0.1, 1.0, 10)
    nis = np.full(10, 0.5)
    nis[6] = 90.0
    fig = plot_gate(t, nis, 6.63, {"no gate": np.linspace(0, 1, 10), "with the gate": np.zeros(10)},
                    outlier_time=t[6])
    left, right = fig.axes
    assert left.get_yscale() == "log" and left.get_ylabel() == "NIS (dimensionless)"
    assert "gate: χ² quantile = 6.63" in [line.get_label() for line in left.lines]
    assert [line.get_label() for line in right.lines][:2] == ["no gate", "with the gate"]
    fig.canvas.draw()
    with pytest.raises(ValueError, match="threshold must be a number > 0"):
        plot_gate(t, nis, -1.0, {"a": np.zeros(10)}, 0.5)
    with pytest.raises(ValueError, match="errors must be a non-empty mapping"):
        plot_gate(t, nis, 6.63, {}, 0.5)


def test_attitude_figure_draws_bias_and_sigmas():
    t = np.linspace(0.1, 10.0, 30)
    b_true = np.tile([0.02, -0.01, 0.005], (30, 1))
    fig = plot_attitude_filter_run(t, b_true + 1e-3, b_true, np.full((30, 3), 1e-3), np.full(30, 0.05),
                                   np.full(30, 1.1), title="demo")
    bias, sigmas = fig.axes
    assert bias.get_ylabel() == "gyroscope bias [mrad/s]" and sigmas.get_ylabel() == "standard deviation [deg]"
    assert bias.get_xscale() == "log" and sigmas.get_yscale() == "log"
    assert bias.lines[1].get_ydata()[0] == pytest.approx(20.0)  # the true b_g,x in mrad/s
    assert [line.get_label() for line in sigmas.lines] == ["tilt (roll/pitch), per axis", "yaw about gravity"]
    fig.canvas.draw()
    linear = plot_attitude_filter_run(np.r_[0.0, t[1:]], b_true, b_true, np.ones((30, 3)), np.ones(30),
                                      np.ones(30), log_time=False)
    assert linear.axes[0].get_xscale() == "linear"
    with pytest.raises(ValueError, match="t must be > 0 for a logarithmic time axis"):
        plot_attitude_filter_run(np.r_[0.0, t[1:]], b_true, b_true, np.ones((30, 3)), np.ones(30), np.ones(30))
    with pytest.raises(ValueError, match=r"bias_sigma must be a finite array of shape \(T, 3\)"):
        plot_attitude_filter_run(t, b_true, b_true, np.ones((30, 2)), np.ones(30), np.ones(30))
