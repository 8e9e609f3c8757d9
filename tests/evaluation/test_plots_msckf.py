"""Tests of evio_lib.evaluation.plots_msckf: figures render to Agg, draw what they claim, reject bad input."""
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from evio_lib.evaluation.plots_msckf import (  # noqa: E402
    correlation_matrix,
    plot_consistency,
    plot_covariance_structure,
    plot_error_growth,
    plot_feature_update_schematic,
    plot_monte_carlo_bounds,
    plot_nees,
    plot_observability_spectrum,
    plot_trajectory_errors,
    plot_triangulation_error,
    plot_unobservable_directions_schematic,
)



def _render(fig) -> np.ndarray:
    """Draw the figure on the Agg canvas and return its pixels (fails on any drawing error)."""
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())


def _spd(rng: np.random.Generator, n: int) -> np.ndarray:
    A = rng.standard_normal((n, n)) * np.exp(rng.uniform(-4, 2, n))[:, None]  # widely different scales
    return A @ A.T + 1e-9 * np.eye(n)


def test_correlation_matrix_matches_numpy_corrcoef(rng):
    """Independent truth: np.corrcoef of samples drawn from P tends to ρ; exactly, ρ = D^-1/2 P D^-1/2."""
    P = _spd(rng, 9)
    rho = correlation_matrix(P)
    d = 1.0 / np.sqrt(np.diag(P))
    np.testing.assert_allclose(rho, d[:, None] * P * d[None, :], atol=1e-12)
    np.testing.assert_allclose(np.diag(rho), 1.0)
    x = rng.multivariate_normal(np.zeros(9), P, size=20000)
    np.testing.assert_allclose(rho, np.corrcoef(x.T), atol=0.03)


def test_correlation_matrix_handles_zero_variance():
    P = np.diag([1.0, 0.0, 4.0])
    P[0, 2] = P[2, 0] = 1.0
    rho = correlation_matrix(P)
    assert rho[1].tolist() == [0.0, 1.0, 0.0]
    assert rho[0, 2] == pytest.approx(0.5)


@pytest.mark.parametrize(
    "P, match",
    [
        (np.ones((2, 3)), r"P must have shape \(n, n\); got \(2, 3\)"),
        (np.array([[1.0, np.nan], [np.nan, 1.0]]), r"P must contain only finite values"),
        (np.diag([1.0, -1.0]), r"P must have a non-negative diagonal"),
    ],
)
def test_correlation_matrix_rejects_bad_input(P, match):
    with pytest.raises(ValueError, match=match):
        correlation_matrix(P)


def test_plot_error_growth_draws_curves_and_power_law_guides():
    t = np.linspace(0.0, 4.0, 41)
    fig = plot_error_growth(t, {"quadratic": 0.5 * t**2, "cubic": t**3 / 6}, loglog=True,
                            guides=[(2.0, 8.0, "t²"), (3.0, 64.0 / 6.0, "t³")])
    ax = fig.axes[0]
    assert len(ax.lines) == 4 and ax.get_xscale() == "log" and ax.get_yscale() == "log"
    # the guide through (t_end, 8) with slope 2 coincides with 0.5 t² (the same power law)
    tg, yg = ax.lines[2].get_data()
    np.testing.assert_allclose(yg, 0.5 * tg**2, rtol=1e-12)
    # log-log drops t = 0, where log is undefined
    assert ax.lines[0].get_xdata().min() > 0
    assert _render(fig).shape[2] == 4


def test_plot_error_growth_rejects_bad_input():
    t = np.linspace(0.0, 1.0, 5)
    with pytest.raises(ValueError, match=r"errors\['a'\] must have shape \(T,\) = \(5,\)"):
        plot_error_growth(t, {"a": np.ones(4)})
    with pytest.raises(ValueError, match=r"errors must be a non-empty mapping"):
        plot_error_growth(t, {})
    with pytest.raises(ValueError, match=r"t must be a finite array of shape \(T,\)"):
        plot_error_growth([0.0], {"a": [1.0]})
    with pytest.raises(ValueError, match=r"guides must be \(power, value > 0"):
        plot_error_growth(t, {"a": t}, guides=[(2.0, -1.0, "bad")])


def test_plot_monte_carlo_bounds_draws_n_sigma_and_sample_spread(rng):
    t = np.linspace(0.0, 1.0, 11)
    sigma = np.column_stack([0.1 + t, 0.2 + t, 0.3 + t, 1 + t, 2 + t, 3 + t])
    errors = rng.standard_normal((50, 11, 6)) * sigma
    fig = plot_monte_carlo_bounds(t, errors, sigma, [f"e{k}" for k in range(6)], max_runs=5)
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert len(axes) == 6
    for k, ax in enumerate(axes):
        lines = ax.lines
        assert len(lines) == 5 + 4  # 5 traces, ±3 std (sample), ±3 σ (filter)
        np.testing.assert_allclose(lines[-2].get_ydata(), 3.0 * sigma[:, k])
        np.testing.assert_allclose(lines[-1].get_ydata(), -3.0 * sigma[:, k])
        np.testing.assert_allclose(lines[5].get_ydata(), 3.0 * errors[:, :, k].std(axis=0))
    _render(fig)


def test_plot_monte_carlo_bounds_rejects_bad_input():
    t = np.linspace(0.0, 1.0, 3)
    with pytest.raises(ValueError, match=r"errors must have shape \(R, T, d\) with T = 3"):
        plot_monte_carlo_bounds(t, np.zeros((2, 4, 3)), np.ones((3, 3)), list("abc"))
    with pytest.raises(ValueError, match=r"sigma must have shape \(T, d\) = \(3, 3\)"):
        plot_monte_carlo_bounds(t, np.zeros((2, 3, 3)), np.ones((3, 2)), list("abc"))
    with pytest.raises(ValueError, match=r"labels must name the d = 3 components"):
        plot_monte_carlo_bounds(t, np.zeros((2, 3, 3)), np.ones((3, 3)), list("ab"))


def test_plot_covariance_structure_shows_correlations_and_blocks(rng):
    P = _spd(rng, 15 + 6 * 3)
    fig = plot_covariance_structure(P)
    ax = fig.axes[0]
    np.testing.assert_allclose(np.asarray(ax.images[0].get_array()), correlation_matrix(P))
    labels = [tick.get_text() for tick in ax.get_xticklabels()]
    assert labels == ["δθ", "δb_g", "δv", "δb_a", "δp", "C1", "C2", "C3"]
    fig2 = plot_covariance_structure(np.diag(np.r_[np.full(15, 1e-4), np.full(6, 1e2)]), correlation=False)
    image = np.asarray(fig2.axes[0].images[0].get_array())
    assert image[0, 0] == pytest.approx(-4.0) and image[20, 20] == pytest.approx(2.0)
    assert image[0, 1] == pytest.approx(-4.0)  # exact zeros shown at the lowest level, not -inf
    _render(fig)


def test_plot_covariance_structure_rejects_non_msckf_size():
    with pytest.raises(ValueError, match=r"P must have shape \(15 \+ 6N, 15 \+ 6N\); got \(16, 16\)"):
        plot_covariance_structure(np.eye(16))


def test_plot_nees_draws_curve_expected_value_and_band():
    t = np.linspace(0.0, 2.0, 21)
    nees = 6.0 + np.sin(t)
    fig = plot_nees(t, nees, (4.58, 7.61), dof=6, n_runs=20)
    ax = fig.axes[0]
    np.testing.assert_allclose(ax.lines[0].get_ydata(), nees)
    assert list(ax.lines[1].get_ydata()) == [6, 6]
    band = ax.collections[0].get_paths()[0].vertices[:, 1]
    assert band.min() == pytest.approx(4.58) and band.max() == pytest.approx(7.61)
    _render(fig)


def test_plot_nees_rejects_bad_input():
    t = np.linspace(0.0, 1.0, 4)
    with pytest.raises(ValueError, match=r"nees must have shape \(T,\) = \(4,\)"):
        plot_nees(t, np.ones(3), (1.0, 2.0), 6, 5)
    with pytest.raises(ValueError, match=r"band must satisfy 0 <= lo < hi"):
        plot_nees(t, np.ones(4), (2.0, 1.0), 6, 5)


def test_plot_consistency_one_line_per_variant_and_bands():
    t = np.linspace(0.0, 3.0, 31)
    curves = {"OC on": {"pose": 6 + 0 * t, "yaw": 1 + 0 * t, "yaw_sigma_deg": 2.9 - 0.1 * t},
              "OC off": {"pose": 8 + t, "yaw": 1 + t, "yaw_sigma_deg": 2.9 - 0.4 * t}}
    fig = plot_consistency(t, curves, (4.6, 7.6), (0.5, 1.7), n_runs=20)
    pose_ax, yaw_ax, sigma_ax = fig.axes
    assert pose_ax.get_yscale() == "log" and sigma_ax.get_yscale() == "linear"
    for ax, key in ((pose_ax, "pose"), (yaw_ax, "yaw"), (sigma_ax, "yaw_sigma_deg")):
        assert len(ax.lines) == 2
        np.testing.assert_allclose(ax.lines[1].get_ydata(), curves["OC off"][key])
    band = yaw_ax.patches[0]  # axhspan: a Rectangle from lo to hi in data coordinates
    assert band.get_y() == pytest.approx(0.5) and band.get_y() + band.get_height() == pytest.approx(1.7)
    _render(fig)


def test_plot_consistency_rejects_bad_input():
    t = np.linspace(0.0, 1.0, 3)
    with pytest.raises(ValueError, match=r"curves\['a'\] lacks \['yaw_sigma_deg'\]"):
        plot_consistency(t, {"a": {"pose": t, "yaw": t}}, (1, 2), (0.1, 2), 3)
    with pytest.raises(ValueError, match=r"curves\['a'\]\['yaw'\] must have shape \(T,\)"):
        plot_consistency(t, {"a": {"pose": t, "yaw": t[:2], "yaw_sigma_deg": t}}, (1, 2), (0.1, 2), 3)
    with pytest.raises(ValueError, match=r"curves must be a non-empty mapping"):
        plot_consistency(t, {}, (1, 2), (0.1, 2), 3)


def test_plot_trajectory_errors_shows_first_estimate_error_in_cm(rng):
    t = np.linspace(0.0, 1.0, 11)
    gt = rng.standard_normal((11, 3))
    est = gt + 0.02
    fig = plot_trajectory_errors(t, gt, {"MSCKF": est, "IMU only": gt + 5.0}, np.full((11, 3), 0.01))
    assert len(fig.axes) == 6
    top, bottom = fig.axes[0], fig.axes[3]
    assert len(top.lines) == 3  # truth + two estimates
    np.testing.assert_allclose(bottom.lines[0].get_ydata(), 2.0)  # 0.02 m = 2 cm
    band = bottom.collections[0].get_paths()[0].vertices[:, 1]
    assert band.max() == pytest.approx(3.0)  # 3 sigma = 3 cm
    _render(fig)


def test_plot_trajectory_errors_rejects_bad_input():
    t = np.linspace(0.0, 1.0, 3)
    with pytest.raises(ValueError, match=r"p_gt must have shape \(T, 3\)"):
        plot_trajectory_errors(t, np.zeros((3, 2)), {"a": np.zeros((3, 3))}, np.ones((3, 3)))
    with pytest.raises(ValueError, match=r"estimates\['a'\] must have shape \(T, 3\)"):
        plot_trajectory_errors(t, np.zeros((3, 3)), {"a": np.zeros((2, 3))}, np.ones((3, 3)))
    with pytest.raises(ValueError, match=r"sigma must be finite standard deviations >= 0"):
        plot_trajectory_errors(t, np.zeros((3, 3)), {"a": np.zeros((3, 3))}, -np.ones((3, 3)))


def test_plot_triangulation_error_one_line_per_noise_level_in_cm():
    views = [2, 3, 5, 10]
    median_error = np.array([[0.10, 0.08, 0.07, 0.065], [0.40, 0.33, 0.29, 0.27]])  # [m]
    fig = plot_triangulation_error(views, median_error, [0.5, 2.0], title="feature at 2.5 m")
    ax = fig.axes[0]
    assert len(fig.axes) == 1 and len(ax.lines) == 2
    for line, row in zip(ax.lines, median_error):
        np.testing.assert_allclose(line.get_xdata(), views)
        np.testing.assert_allclose(line.get_ydata(), 100 * row)  # metres -> centimetres
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["0.5 px noise", "2 px noise"]
    assert ax.get_title() == "feature at 2.5 m" and ax.get_ylabel() == "median position error [cm]"
    _render(fig)
    legend_box = ax.get_legend().get_window_extent()
    assert legend_box.x0 >= ax.get_window_extent().x1  # the legend sits beside the axes, over no curve


def test_plot_triangulation_error_rejects_bad_input():
    with pytest.raises(ValueError, match=r"median_error must have shape \(L, V\) = \(2, 3\)"):
        plot_triangulation_error([2, 3, 5], np.ones((3, 2)), [1.0, 2.0])
    with pytest.raises(ValueError, match=r"view_counts must be a non-empty \(V,\) array of counts >= 1"):
        plot_triangulation_error([0, 3], np.ones((1, 2)), [1.0])
    with pytest.raises(ValueError, match=r"noise_levels_px must be a non-empty \(L,\) array"):
        plot_triangulation_error([2, 3], np.ones((0, 2)), [])


def test_every_axis_is_labelled_and_every_line_style_is_in_a_legend(rng):
    """Issue 27: axes with units (or 'dimensionless'), a legend entry for each line style, whatever the title."""
    t = np.linspace(0.0, 1.0, 6)
    mc = plot_monte_carlo_bounds(t, rng.normal(size=(4, 6, 3)), np.ones((6, 3)), ["x [m]", "y [m]", "z [m]"],
                                 title="a custom title")  # the suptitle no longer explains the styles
    labels = [text.get_text() for text in mc.axes[0].get_legend().get_texts()]
    assert labels == ["Monte-Carlo runs (4 drawn)", "filter ±3σ", "sample ±3 std over 4 runs"]
    nees = plot_nees(t, np.full(6, 6.0), (4.6, 7.6), dof=6, n_runs=20)
    assert nees.axes[0].get_ylabel() == "NEES (dimensionless)"
    c = {"OC on": {"pose": np.full(6, 6.0), "yaw": np.ones(6), "yaw_sigma_deg": np.ones(6)}}
    consistency = plot_consistency(t, c, (4.6, 7.6), (0.5, 1.7), n_runs=20)
    assert all(ax.get_ylabel() and ax.get_xlabel() == "t [s]" for ax in consistency.axes)
    assert [ax.get_yscale() for ax in consistency.axes] == ["log", "log", "linear"]
    trajectory = plot_trajectory_errors(t, np.zeros((6, 3)), {"MSCKF": np.zeros((6, 3))}, np.ones((6, 3)))
    assert [ax.get_ylabel() for ax in trajectory.axes] == ["x [m]", "y [m]", "z [m]",
                                                         "error x [cm]", "error y [cm]", "error z [cm]"]
    for fig in (mc, nees, consistency, trajectory):
        _render(fig)


def test_power_law_guides_have_distinct_line_styles():
    fig = plot_error_growth([0.0, 1.0, 2.0], {"a": [0.0, 0.1, 0.4]}, loglog=True,
                            guides=[(2, 0.4, "t^2"), (3, 0.4, "t^3")])
    styles = [line.get_linestyle() for line in fig.axes[0].lines[1:]]
    assert styles == ["--", ":"] and [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == ["a", "t^2", "t^3"]


def test_plot_triangulation_error_draws_two_standard_error_bars():
    views = [2, 5]
    median_error = np.array([[0.5, 0.4]])
    fig = plot_triangulation_error(views, median_error, [1.0], standard_error=[[0.01, 0.02]])
    ax = fig.axes[0]
    bars = ax.containers[0].lines[2][0].get_segments()  # the vertical bar of each point
    np.testing.assert_allclose([seg[:, 1] for seg in bars], [[48.0, 52.0], [36.0, 44.0]])  # ±2 SE in cm
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["1 px noise", "±2 standard errors of the median"]
    with pytest.raises(ValueError, match=r"standard_error must hold finite values >= 0 of shape \(L, V\)"):
        plot_triangulation_error(views, median_error, [1.0], standard_error=[[0.01]])
    _render(fig)


def test_plot_observability_spectrum_sorts_and_normalises_each_matrix():
    rng = np.random.default_rng(0)
    O = rng.standard_normal((40, 6)) @ np.diag([1.0, 1.0, 0.0, 2.0, 5.0, 0.5])  # one unobservable direction
    sv = np.linalg.svd(O, compute_uv=False)
    fig = plot_observability_spectrum({"O": sv, "scaled": 10 * sv}, n_unobservable=1)
    ax = fig.axes[0]
    assert ax.get_yscale() == "log" and ax.get_xlabel() == "singular value index (smallest first)"
    first, second = ax.lines[0].get_ydata(), ax.lines[1].get_ydata()
    np.testing.assert_allclose(first[1:], np.sort(sv)[1:] / sv.max())  # sorted, relative to the largest
    np.testing.assert_allclose(first, second)  # the scale of O does not matter
    assert first[0] < 1e-14 < first[1]  # the zero singular value, at the floor of the log axis
    assert ax.lines[2].get_xdata()[0] == 1.5  # the separator after the unobservable directions
    with pytest.raises(ValueError, match=r"singular_values\['bad'\] must be a \(n,\) array of finite values >= 0"):
        plot_observability_spectrum({"bad": [-1.0, 1.0]})
    with pytest.raises(ValueError, match=r"singular_values must be a non-empty mapping"):
        plot_observability_spectrum({})
    _render(fig)


def test_schematics_draw_their_panels():
    update = plot_feature_update_schematic(num_clones=4)
    assert [ax.get_title()[:3] for ax in update.axes] == ["(a)", "(b)", "(c)"]
    texts = " ".join(t.get_text() for ax in update.axes for t in ax.texts)
    assert "C4" in texts and "C5" not in texts  # one glyph per clone
    assert "W_i = L_i⁻¹" in texts and "r_o = Aᵀ r" in texts
    with pytest.raises(ValueError, match=r"num_clones must be an integer >= 2"):
        plot_feature_update_schematic(num_clones=1)
    directions = plot_unobservable_directions_schematic()
    titles = [ax.get_title() for ax in directions.axes]
    assert "unobservable (3)" in titles[0] and "unobservable (1)" in titles[1] and "observable" in titles[2]
    for fig in (update, directions):
        _render(fig)
