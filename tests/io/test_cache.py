"""Tests of evio_lib.io.cache: exact npz round trip of a Sequence, metadata encoding, errors."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.events.array import make_events
from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.io.cache import from_json_value, load_sequence_npz, save_sequence_npz, to_json_value
from evio_lib.io.errors import DataFileError
from evio_lib.sequence import GroundTruth, ImuSamples, Sequence


def _sequence(rng: np.random.Generator) -> Sequence:
    n = 20000
    events = make_events(np.sort(rng.uniform(0, 2, n)), rng.integers(0, 240, n), rng.integers(0, 180, n), rng.choice([-1, 1], n))
    t_gt = np.linspace(0.0, 2.0, 41)
    q = Rotation.random(41, random_state=np.random.RandomState(5)).as_quat()
    return Sequence(
        "cached",
        camera=PinholeRadtan.davis240c(),
        events=events,
        frame_times=np.array([0.1, 0.6]),
        frames=rng.integers(0, 256, (2, 180, 240), dtype=np.uint8),
        imu=ImuSamples(np.arange(400) / 200.0, rng.normal(size=(400, 3)), rng.normal(size=(400, 3))),
        groundtruth=GroundTruth(t_gt, rng.normal(size=(41, 3)), q, body="camera"),
        groundtruth_imu=GroundTruth(t_gt, rng.normal(size=(41, 3)), q[::-1].copy(), body="imu",
                                    bias_gyro=rng.normal(size=(41, 3)), bias_accel=rng.normal(size=(41, 3))),
        R_CtoI=Rotation.from_euler("y", 0.3).as_matrix(),
        p_CinI=np.array([0.1, 0.0, -0.05]),
        metadata={"imu_noise": {"gyroscope_noise_density": 1e-4}, "gravity_G": np.array([0.0, 0.0, -9.81]),
                  "size": (240, 180), "tags": ["sim", 3, None, True], "third": 1 / 3, "counts": np.arange(4, dtype=np.int32)},
    )


@pytest.mark.parametrize("compress", [False, True])
def test_round_trip_is_exact(tmp_path, rng, compress):
    seq = _sequence(rng)
    path = save_sequence_npz(seq, tmp_path / "seq.cache", compress=compress)
    assert path == tmp_path / "seq.cache" and path.is_file()  # no ".npz" appended
    back = load_sequence_npz(path)
    back.validate()
    assert back.name == seq.name and back.camera == seq.camera
    for name in ("events", "frame_times", "frames", "R_CtoI", "p_CinI"):
        np.testing.assert_array_equal(getattr(back, name), getattr(seq, name), err_msg=name)
        assert getattr(back, name).dtype == getattr(seq, name).dtype, name
    for name in ("t", "gyro", "accel"):
        np.testing.assert_array_equal(getattr(back.imu, name), getattr(seq.imu, name))
    for gt_name in ("groundtruth", "groundtruth_imu"):
        a, b = getattr(seq, gt_name), getattr(back, gt_name)
        assert a.body == b.body
        for name in ("t", "p_BinG", "q_GtoB", "v_BinG", "bias_gyro", "bias_accel"):
            x, y = getattr(a, name), getattr(b, name)
            assert (x is None) == (y is None)
            if x is not None:
                np.testing.assert_array_equal(x, y)
    md = back.metadata
    assert md["size"] == (240, 180) and md["tags"] == ["sim", 3, None, True] and md["third"] == 1 / 3
    assert md["counts"].dtype == np.int32 and md["counts"].tolist() == [0, 1, 2, 3]
    np.testing.assert_array_equal(md["gravity_G"], [0.0, 0.0, -9.81])


def test_round_trip_of_an_empty_sequence(tmp_path):
    back = load_sequence_npz(save_sequence_npz(Sequence("nothing"), tmp_path / "e.npz"))
    back.validate()
    assert back.events.shape == (0,) and back.frames.shape == (0, 0, 0) and back.imu is None
    assert back.groundtruth is None and back.camera is None and back.R_CtoI is None and back.metadata == {}


def test_json_value_encoding():
    value = {"a": (1, 2.5), "b": [np.float32(0.5), np.int64(3)], "c": np.eye(2, dtype=np.float32), "d": {"e": None}}
    back = from_json_value(to_json_value(value))
    assert back["a"] == (1, 2.5) and back["b"] == [0.5, 3] and back["d"] == {"e": None}
    assert back["c"].dtype == np.float32 and np.array_equal(back["c"], np.eye(2))
    with pytest.raises(ValueError, match=r"metadata must have str keys only \(JSON\); got key 1 of type int"):
        to_json_value({1: "x"})
    with pytest.raises(ValueError, match=r"metadata\['f'\] must be JSON-like .* got function"):
        to_json_value({"f": lambda: 0})


def test_errors(tmp_path, rng):
    with pytest.raises(DataFileError, match=r"none.npz: file not found"):
        load_sequence_npz(tmp_path / "none.npz")
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(DataFileError, match=r"other.npz: not an evio sequence cache \(no 'header' entry\)"):
        load_sequence_npz(tmp_path / "other.npz")
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(DataFileError, match=r"text.npz: not a readable npz file"):
        load_sequence_npz(tmp_path / "text.npz")
    seq = _sequence(rng)
    seq.metadata["bad"] = object()
    with pytest.raises(ValueError, match=r"metadata\['bad'\] must be JSON-like"):
        save_sequence_npz(seq, tmp_path / "x.npz")
    with pytest.raises(ValueError, match="sequence must be a Sequence; got str"):
        save_sequence_npz("seq", tmp_path / "x.npz")


def test_real_slider_events_through_cache(real_data_dir, tmp_path):
    from evio_lib.io.ecd import read_ecd_events

    events = read_ecd_events(real_data_dir / "ecd_slider_depth_slice" / "slider_seg.txt")
    seq = Sequence("slider_depth", camera=PinholeRadtan.davis240c(), events=events)
    back = load_sequence_npz(save_sequence_npz(seq, tmp_path / "slider.npz"))
    np.testing.assert_array_equal(back.events, events)
    assert back.sensor_size == (240, 180) and back.frames.shape == (0, 180, 240)


def _tampered(tmp_path, rng, **changes):
    """Write a valid cache, then rewrite it with some entries replaced (None removes the entry); return its path."""
    path = save_sequence_npz(_sequence(rng), tmp_path / "seq.npz")
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    for key, value in changes.items():
        if value is None:
            arrays.pop(key)
        else:
            arrays[key] = value(arrays[key]) if callable(value) else value
    bad = tmp_path / "bad.npz"
    np.savez(bad, **arrays)
    return bad


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"events": lambda ev: ev[::-1].copy()}, r"bad.npz: the cached sequence is not valid \(events must be sorted by time"),
        ({"events": lambda ev: np.stack([ev["t"], ev["x"], ev["y"], ev["p"]], axis=1)},
         r"bad.npz: the cached sequence is not valid \(events must be a 1-D NumPy array of dtype EVENT_DTYPE"),
        ({"frames": lambda f: f[:1]}, r"bad.npz: .*frames must have shape \(2, H, W\) matching frame_times"),
        ({"imu_t": lambda t: t[::-1].copy()}, r"bad.npz: .*imu.t must be strictly increasing"),
        ({"R_CtoI": np.eye(2)}, r"bad.npz: .*R_CtoI must be a finite \(3, 3\) rotation matrix"),
        ({"frames": None}, r"bad.npz: the cached sequence is not valid \(missing entry 'frames'\)"),
    ],
)
def test_damaged_cache_is_a_clear_error(tmp_path, rng, changes, message):
    bad = _tampered(tmp_path, rng, **changes)
    before = bad.read_bytes()
    with pytest.raises(DataFileError, match=message):
        load_sequence_npz(bad)
    assert bad.read_bytes() == before
