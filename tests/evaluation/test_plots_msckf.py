"""Tests of evio_lib.evaluation.plots_msckf: figures render to Agg, draw what they claim, reject bad input."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from evio_lib.evaluation.plots_msckf import (  # noqa: E402
    correlation_matrix,
    plot_covariance_structure,
    plot_error_growth,
    plot_monte_carlo_bounds,
)


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


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
