"""Tests of evio_lib.evaluation.plots_schematics: each schematic is a Figure that draws and names its parts."""
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from evio_lib.evaluation.plots_schematics import (  # noqa: E402
    _pixel_events,
    homographic_adaptation_schematic_data,
    plot_homographic_adaptation_schematic,
    plot_event_pixel_schematic,
    plot_msckf_schematic,
    plot_pipeline_schematic,
    plot_reconstruction_schematic,
    plot_superpoint_schematic,
)


def _texts(fig: Figure) -> str:
    """Return every text of the figure (axes texts, titles, axis labels, legend entries) joined by newlines."""
    parts = []
    for ax in fig.axes:
        parts += [t.get_text() for t in ax.texts]
        parts += [ax.get_title(), ax.get_xlabel(), ax.get_ylabel()]
        legend = ax.get_legend()
        if legend is not None:
            parts += [t.get_text() for t in legend.get_texts()]
    return "\n".join(parts)


def _drawn(fig: Figure) -> None:
    fig.canvas.draw()  # fails on any drawing error
    assert np.asarray(fig.canvas.buffer_rgba()).std() > 0


def test_event_pixel_schematic_names_the_circuit_and_labels_the_curve() -> None:
    fig = plot_event_pixel_schematic(contrast=0.2)
    assert isinstance(fig, Figure) and len(fig.axes) == 2
    _drawn(fig)
    text = _texts(fig)
    for label in ("photoreceptor", "differencing", "comparator", "ON event", "OFF event", "reset", "time t [s]",
                  "log intensity L = log I [log units]", "log intensity L(t)", "levels r0 + k C"):
        assert label in text, label


def test_event_pixel_schematic_events_follow_the_threshold_rule() -> None:
    t = np.linspace(0.0, 1.0, 1001)
    curve = 0.9 * t  # a ramp: 0.9 / 0.2 = 4 ON events at 0.2, 0.4, 0.6, 0.8 log units
    times, polarities, levels = _pixel_events(t, curve, 0.2)
    assert polarities == [1, 1, 1, 1]
    np.testing.assert_allclose(levels, [0.2, 0.4, 0.6, 0.8])
    np.testing.assert_allclose(times, np.array(levels) / 0.9, atol=1e-9)


def test_event_pixel_schematic_rejects_a_bad_contrast() -> None:
    with pytest.raises(ValueError, match="contrast must be a positive"):
        plot_event_pixel_schematic(contrast=0.0)


def test_reconstruction_schematic_shows_voxels_network_state_and_frame() -> None:
    fig = plot_reconstruction_schematic(num_bins=5, channels=16)
    assert isinstance(fig, Figure)
    _drawn(fig)
    text = _texts(fig)
    for label in ("window k − 1", "window k", "voxel grid\n5 x H x W", "encoder", "ConvGRU", "decoder",
                  "state h_{k−1} carried to window k", "frame", "N_e = n H W"):
        assert label in text, label
    with pytest.raises(ValueError, match="num_bins must be a positive integer"):
        plot_reconstruction_schematic(num_bins=0)


def test_superpoint_schematic_has_the_library_sizes() -> None:
    fig = plot_superpoint_schematic()
    assert isinstance(fig, Figure)
    _drawn(fig)
    text = _texts(fig)
    for label in ("shared encoder: H x W -> H/8 x W/8 x 128", "detector head", "descriptor head", "conv1x1\n65 ch",
                  "softmax over 65", "depth-to-space", "heatmap\nH x W", "conv1x1\n256 ch", "bicubic upsampling",
                  "L2 normalise", "descriptors\nH x W x 256", "2 x conv3x3\n128, 128", "H/8 x W/8"):
        assert label in text, label
    with pytest.raises(ValueError, match="encoder_channels must be 8"):
        plot_superpoint_schematic(encoder_channels=(64, 64))


def test_superpoint_schematic_matches_the_network() -> None:
    from evio_lib.features.network import SuperPointNet

    config = SuperPointNet().config
    text = _texts(plot_superpoint_schematic(config["encoder_channels"], config["head_channels"],
                                            config["descriptor_dim"]))
    assert f"conv3x3\n{config['head_channels']}" in text and f"H x W x {config['descriptor_dim']}" in text


def test_homographic_adaptation_schematic_names_every_step() -> None:
    fig = plot_homographic_adaptation_schematic(n_homographies=6)
    assert isinstance(fig, Figure)
    _drawn(fig)
    text = _texts(fig) + "\n" + "\n".join(t.get_text() for t in fig.texts)
    for label in ("image I (no labels)", "H_1", "H_3", "view H_i I", "detector f(H_i I)", "H_i⁻¹ f(H_i I)",
                  "aggregate F(I)", "threshold\n+ NMS", "maxima of F(I)", "N = 6", "2 more random views",
                  "detector response (÷ its peak on I)", "(c_i = 0)", "image 2 = image 1 warped by H", "s = 1",
                  "s = 0", "m_p = 1", "m_n = 0.2", "d·d′: cosine of the two cells' unit descriptors",
                  "loss of one cell pair\n(positive term ÷ λ_d = 62.5)"):
        assert label in text, label


def test_homographic_adaptation_schematic_draws_the_library_computation() -> None:
    import torch

    from evio_lib.features.training.adaptation import homographic_adaptation
    from evio_lib.features.training.augment import HOMOGRAPHIC_ADAPTATION
    from evio_lib.features.training.losses import cell_correspondences
    from evio_lib.evaluation.plots_schematics import _harris_response

    data = homographic_adaptation_schematic_data(n_homographies=6)
    Hs = data["homographies"]
    assert Hs.shape == (6, 3, 3) and np.allclose(Hs[0], np.eye(3))
    again = homographic_adaptation(data["image"], lambda b: _harris_response(b) / data["scale"], rng=0,
                                   homographies=Hs, config=HOMOGRAPHIC_ADAPTATION.replace(valid_border_margin=5))
    np.testing.assert_array_equal(again.heatmap, data["heatmap"])
    assert data["heatmap"].max() <= 1.0 + 1e-6 and len(data["labels"]) > 10  # the corners of the drawing
    # the drawn views' responses mapped back agree with the aggregate's inputs: 0 <= back, NaN only off the view
    assert np.all(np.nan_to_num(data["back"]) >= 0) and np.isnan(data["back"]).any()
    # the green cells are the row of Eq. 10's S for the drawn cell
    rows, cols = data["image"].shape[0] // 8, data["image"].shape[1] // 8
    S = cell_correspondences(torch.as_tensor(data["pair_homography"]), (rows, cols))[0].numpy()
    r, c = data["cell"]
    expected = np.argwhere(S[r * cols + c].reshape(rows, cols) > 0)
    np.testing.assert_array_equal(np.sort(expected, axis=0), np.sort(data["positives"], axis=0))
    assert 1 <= len(data["positives"]) <= 5


def test_homographic_adaptation_schematic_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="n_homographies must be an integer >= 4"):
        plot_homographic_adaptation_schematic(n_homographies=3)
    with pytest.raises(ValueError, match="margins must be"):
        plot_homographic_adaptation_schematic(margins=(0.2, 1.0))
    with pytest.raises(ValueError, match="lambda_d must be a positive"):
        plot_homographic_adaptation_schematic(lambda_d=0.0)


def test_msckf_schematic_shows_the_state_order_and_the_track_life() -> None:
    fig = plot_msckf_schematic(num_clones=5)
    assert isinstance(fig, Figure) and len(fig.axes) == 2
    _drawn(fig)
    state_texts = [t.get_text() for t in fig.axes[0].texts]
    imu = [s for s in state_texts if s in ("q_GtoI", "b_g", "v_IinG", "b_a", "p_IinG")]
    assert imu == ["q_GtoI", "b_g", "v_IinG", "b_a", "p_IinG"]  # the order of evio_lib.msckf.state
    text = _texts(fig)
    for label in ("15 error states", "6 error states each", "q_GtoC1", "p_CNinG", "track lost", "triangulate",
                  "nullspace projection", "EKF update", "marginalised", "C5"):
        assert label in text, label
    with pytest.raises(ValueError, match="num_clones must be an integer >= 3"):
        plot_msckf_schematic(num_clones=2)


def test_pipeline_schematic_shows_the_data_flow() -> None:
    fig = plot_pipeline_schematic()
    assert isinstance(fig, Figure)
    _drawn(fig)
    text = _texts(fig)
    for label in ("events (t, x, y, p)", "APS frames", "IMU", "frames", "features", "two-point RANSAC", "MSCKF",
                  "trajectory", "metrics\nATE, RMSE", "ground truth", "feature tracks"):
        assert label in text, label
