"""Tests of evio_lib.evaluation.plots_sim: figures render to Agg; event_rate agrees with numpy.histogram."""
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from evio_lib.events.array import empty_events, make_events  # noqa: E402
from evio_lib.evaluation.plots_sim import (  # noqa: E402
    event_rate,
    plot_event_cloud,
    plot_event_rates,
    plot_image_row,
    plot_image_table,
    plot_imu_vs_truth,
    plot_pixel_events,
    plot_sample_intervals,
)


@pytest.fixture
def events(rng: np.random.Generator) -> np.ndarray:
    n = 5000
    t = np.sort(rng.uniform(0.0, 1.0, n))
    return make_events(t, rng.integers(0, 40, n), rng.integers(0, 30, n), rng.choice([-1, 1], n))



def _render(fig) -> np.ndarray:
    """Draw the figure on the Agg canvas and return its pixels (fails on any drawing error)."""
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())


def test_event_rate_matches_numpy_histogram(events: np.ndarray) -> None:
    centres, rate = event_rate(events, 0.0, 1.0, bin_s=0.05)
    counts, edges = np.histogram(events["t"], bins=np.linspace(0.0, 1.0, 21))
    assert centres.shape == (20,)
    np.testing.assert_allclose(centres, 0.5 * (edges[:-1] + edges[1:]))
    np.testing.assert_allclose(rate * 0.05, counts)
    assert rate.sum() * 0.05 == len(events)


def test_event_rate_drops_partial_bin_and_checks_input(events: np.ndarray) -> None:
    centres, rate = event_rate(events, 0.0, 0.33, bin_s=0.1)
    assert centres.shape == rate.shape == (3,)
    with pytest.raises(ValueError, match="bin_s must be in"):
        event_rate(events, 0.0, 1.0, bin_s=0.0)
    with pytest.raises(ValueError, match="t_end > t_start"):
        event_rate(events, 1.0, 1.0)
    with pytest.raises(ValueError, match="EVENT_DTYPE"):
        event_rate(np.zeros(3), 0.0, 1.0)


def test_pixel_events_figure_draws_levels_and_events() -> None:
    t = np.linspace(0.0, 1.0, 101)
    log_i = 0.5 * t
    fig = plot_pixel_events(t, log_i, make_events([0.4, 0.8], [0, 0], [0, 0], [1, 1]), contrast=0.2)
    image = _render(fig)
    assert image.ndim == 3 and image.shape[2] == 4
    top = fig.axes[0]
    assert len(top.collections) == 2  # ON and OFF scatter
    assert top.collections[0].get_offsets().shape == (2, 2)  # two ON events
    with pytest.raises(ValueError, match="contrast must be"):
        plot_pixel_events(t, log_i, empty_events(), contrast=0.0)
    with pytest.raises(ValueError, match="same shape"):
        plot_pixel_events(t, log_i[:-1], empty_events(), contrast=0.2)


def test_image_row_symmetric_range(rng: np.random.Generator) -> None:
    signed = rng.integers(-3, 2, (30, 40)).astype(float)
    fig = plot_image_row([rng.random((30, 40)), signed], ["frame", "events"], cmaps=["gray", "bwr"],
                         symmetric=[False, True], colorbar=True)
    _render(fig)
    lo, hi = fig.axes[1].images[0].get_clim()
    assert lo == -hi == -3.0
    with pytest.raises(ValueError, match="equally long"):
        plot_image_row([signed], ["a", "b"])
    with pytest.raises(ValueError, match=r"shape \(H, W\)"):
        plot_image_row([np.zeros(3)], ["a"])


def test_image_row_shares_one_colour_range_and_labels_its_colour_bars(rng: np.random.Generator) -> None:
    small, large = rng.uniform(-0.1, 0.1, (30, 40)), rng.uniform(-2.0, 3.0, (30, 40))
    fig = plot_image_row([small, large], ["residual", "change"], cmaps="bwr", symmetric=True, colorbar=True,
                         vrange="shared", colorbar_label="change [log units]")
    _render(fig)
    assert fig.axes[0].images[0].get_clim() == fig.axes[1].images[0].get_clim() == (-large.max(), large.max())
    assert [ax.get_ylabel() for ax in fig.axes[2:]] == ["change [log units]"] * 2
    fig = plot_image_row([small, large], ["a", "b"], vrange=[(0.0, 1.0), None])
    assert fig.axes[0].images[0].get_clim() == (0.0, 1.0) and fig.axes[1].images[0].get_clim() == (large.min(),
                                                                                                   large.max())
    with pytest.raises(ValueError, match="vrange must be"):
        plot_image_row([small], ["a"], vrange="own")
    with pytest.raises(ValueError, match="one per image"):
        plot_image_row([small, large], ["a", "b"], vrange=[(0.0, 1.0)])


def test_image_table_one_range_per_column(rng: np.random.Generator) -> None:
    calm = [rng.uniform(0, 1, (18, 24)), rng.integers(0, 3, (18, 24)), rng.uniform(1.0, 4.0, (18, 24))]
    fast = [rng.uniform(0, 1, (18, 24)), rng.integers(0, 9, (18, 24)), rng.uniform(200.0, 260.0, (18, 24))]
    fig = plot_image_table([calm, fast], ["calm", "fast"], ["frame", "events", "depth"],
                           ["intensity", "events per pixel", "depth [m]"], cmaps=["gray", "gray_r", "viridis"],
                           vranges=[(0.0, 1.0), None, None], log_scale=[False, False, True])
    _render(fig)
    panels = np.array(fig.axes[:6]).reshape(2, 3)
    for c in range(3):
        assert panels[0, c].images[0].get_clim() == panels[1, c].images[0].get_clim()
    assert panels[0, 0].images[0].get_clim() == (0.0, 1.0)
    assert panels[0, 1].images[0].get_clim() == (0.0, float(max(calm[1].max(), fast[1].max())))
    assert panels[0, 2].images[0].norm.__class__.__name__ == "LogNorm"
    assert [ax.get_xlabel() for ax in fig.axes[6:]] == ["intensity", "events per pixel", "depth [m]"]
    assert [panels[r, 0].get_ylabel() for r in range(2)] == ["calm", "fast"]
    with pytest.raises(ValueError, match="equally long"):
        plot_image_table([calm, fast[:2]], ["a", "b"], ["x", "y", "z"], ["x", "y", "z"])
    with pytest.raises(ValueError, match="row_labels"):
        plot_image_table([calm], ["a", "b"], ["x", "y", "z"], ["x", "y", "z"])


def test_event_cloud_thins_deterministically(events: np.ndarray) -> None:
    fig = plot_event_cloud(events, max_points=1000)
    _render(fig)
    drawn = fig.axes[0].collections[0]
    assert len(drawn.get_offsets()) == 1000  # every 5th of 5000
    assert fig.axes[0].get_title().endswith("(5000 events, every 5th shown)")
    assert [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == ["ON event (p = +1)", "OFF event (p = -1)"]
    assert plot_event_cloud(events[:10]).axes[0].get_title().endswith("(10 events, all shown)")
    with pytest.raises(ValueError, match="at least one event"):
        plot_event_cloud(empty_events())
    with pytest.raises(ValueError, match="max_points"):
        plot_event_cloud(events, max_points=0)


def test_imu_rates_and_sampling_figures(rng: np.random.Generator, events: np.ndarray) -> None:
    t = np.linspace(0.0, 1.0, 200)
    truth = np.column_stack([np.sin(t), np.cos(t), t])
    fig = plot_imu_vs_truth(t, truth + 0.01 * rng.standard_normal((200, 3)), truth, truth, truth)
    _render(fig)
    assert len(fig.axes) == 6
    with pytest.raises(ValueError, match=r"accel_true must have shape \(N, 3\)"):
        plot_imu_vs_truth(t, truth, truth, truth, truth[:, :2])
    centres, rate = event_rate(events, 0.0, 1.0, 0.1)
    fig = plot_event_rates({"a": (centres, rate), "b": (centres, 2 * rate)}, {"a": (t, truth[:, 0])})
    _render(fig)
    assert len(fig.axes) == 3  # two panels + one twin axis
    assert fig.axes[0].get_ylim() == fig.axes[1].get_ylim()  # one rate axis for both sequences
    fig = plot_event_rates({"a": (centres, rate), "b": (centres, 2 * rate)},
                           {"a": (t, truth[:, 0]), "b": (t, 5 * truth[:, 0])})
    assert fig.axes[2].get_ylim() == fig.axes[3].get_ylim()  # ... and one motion axis
    fig = plot_event_rates({"a": (centres, rate), "b": (centres, 2 * rate)}, shared_axes=False)
    assert fig.axes[0].get_ylim() != fig.axes[1].get_ylim()
    with pytest.raises(ValueError, match="at least one"):
        plot_event_rates({})
    fig = plot_sample_intervals(np.cumsum(rng.uniform(1e-3, 1e-2, 50)), t, truth[:, 0])
    _render(fig)
    assert len(fig.axes) == 2
    with pytest.raises(ValueError, match="strictly increasing"):
        plot_sample_intervals([0.0, 0.0, 1.0])


def test_every_line_style_is_in_a_legend_and_axes_carry_units() -> None:
    pixel = plot_pixel_events([0.0, 0.5, 1.0], [0.0, 0.5, 0.0], make_events([0.4], [0], [0], [1]), 0.2)
    labels = [t.get_text() for t in pixel.axes[0].get_legend().get_texts()]
    assert labels == ["levels r0 + k C", "log intensity L(t)", "ON event", "OFF event"]
    assert pixel.axes[0].get_ylabel().endswith("[log units]")
    rates = plot_event_rates({"a": ([0.0, 1.0], [10.0, 20.0])}, {"a": ([0.0, 1.0], [0.1, 0.2])})
    assert [t.get_text() for t in rates.axes[0].get_legend().get_texts()] == [
        "event rate (left axis)", "angular speed |w| (right axis)"]
    intervals = plot_sample_intervals([0.0, 0.1, 0.15, 0.17], [0.0, 0.17], [1.0, 2.0])
    assert [t.get_text() for t in intervals.axes[0].get_legend().get_texts()] == [
        "render interval", "image speed (right axis)"]
