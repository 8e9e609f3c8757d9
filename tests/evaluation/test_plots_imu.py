"""Tests of evio_lib.evaluation.plots_imu: the figure renders to Agg, draws the given curves, rejects bad input."""
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from evio_lib.evaluation.plots_imu import (  # noqa: E402
    plot_imu_model_schematic,
    plot_pose_errors,
    specific_force_in_body,
)



def test_plot_pose_errors_draws_each_run_in_each_panel():
    t = np.linspace(0.0, 2.0, 21)
    errors = {"a": (t, 2 * t, 3 * t), "b": (t**2, t**2, t**3)}
    fig = plot_pose_errors(t, errors, title="demo")
    assert len(fig.axes) == 3
    for k, ax in enumerate(fig.axes):
        assert len(ax.lines) == 2 and ax.get_yscale() == "log"
        x, y = ax.lines[0].get_data()
        np.testing.assert_allclose(x, t[1:])  # the first sample (0, not drawable on log axes) is left out
        np.testing.assert_allclose(y, errors["a"][k][1:])
    assert [ax.get_ylabel() for ax in fig.axes] == ["attitude error [deg]", "velocity error [m/s]",
                                                    "position error [m]"]
    fig.canvas.draw()
    linear = plot_pose_errors(t, errors, log=False)
    assert linear.axes[2].get_yscale() == "linear" and len(linear.axes[2].lines[1].get_xdata()) == 21


def test_plot_pose_errors_rejects_bad_input():
    t = np.linspace(0.0, 1.0, 5)
    with pytest.raises(ValueError, match=r"errors\['a'\] position error \[m\] must have shape \(T,\) = \(5,\)"):
        plot_pose_errors(t, {"a": (t, t, t[:4])})
    with pytest.raises(ValueError, match=r"must be \(attitude, velocity, position\) arrays; got 2 items"):
        plot_pose_errors(t, {"a": (t, t)})
    with pytest.raises(ValueError, match=r"errors must be a non-empty mapping"):
        plot_pose_errors(t, {})
    with pytest.raises(ValueError, match=r"t must be a finite array of shape \(T,\), T >= 2"):
        plot_pose_errors([0.0], {"a": ([0.0], [0.0], [0.0])})


def test_imu_schematic_draws_the_specific_force_to_scale():
    fig = plot_imu_model_schematic(tilt_deg=20.0, accel_G=(4.0, 0.0))
    forces, blocks = fig.axes
    assert (forces.get_xlabel(), forces.get_ylabel()) == ("x_G [m/s²]", "z_G (up) [m/s²]")
    assert "(7.11, 7.85) m/s²" in forces.get_title()  # (4, 9.81) seen from a body pitched by 20 degrees
    assert not blocks.axison and any("gyroscope" in t.get_text() for t in blocks.texts)
    fig.canvas.draw()
    with pytest.raises(ValueError, match="tilt_deg must be a pitch within"):
        plot_imu_model_schematic(tilt_deg=80.0)


def test_specific_force_at_rest_is_one_g_up_and_follows_the_tilt():
    np.testing.assert_allclose(specific_force_in_body(0.0, (0.0, 0.0)), [0.0, 9.81])
    np.testing.assert_allclose(specific_force_in_body(90.0, (0.0, 0.0)), [9.81, 0.0], atol=1e-12)  # nose up
    np.testing.assert_allclose(specific_force_in_body(0.0, (0.0, -9.81)), [0.0, 0.0])  # free fall reads zero
    with pytest.raises(ValueError, match=r"accel_G must be a finite \(a_x, a_z\) pair"):
        specific_force_in_body(0.0, (1.0, 2.0, 3.0))
