"""Tests of evio_lib.sequence: ImuSamples, GroundTruth (rotations, interpolation) and Sequence (validate, slice)."""
import copy

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from evio_lib.events.array import EVENT_DTYPE, events_between, make_events
from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.sequence import GroundTruth, ImuSamples, Sequence


def _random_gt(rng: np.random.Generator, k: int = 20, body: str = "imu", extras: bool = True) -> GroundTruth:
    t = np.cumsum(rng.uniform(0.01, 0.1, k))
    q = Rotation.random(k, random_state=np.random.RandomState(int(rng.integers(1 << 31)))).as_quat()
    return GroundTruth(t=t, p_BinG=rng.normal(size=(k, 3)), q_GtoB=q, body=body,
                       v_BinG=rng.normal(size=(k, 3)) if extras else None,
                       bias_gyro=rng.normal(size=(k, 3)) * 0.01 if extras else None,
                       bias_accel=rng.normal(size=(k, 3)) * 0.1 if extras else None)


def _full_sequence(rng: np.random.Generator) -> Sequence:
    cam = PinholeRadtan(fx=200.0, fy=210.0, cx=31.5, cy=23.5, width=64, height=48, k1=-0.1)
    n = 1000
    events = make_events(np.sort(rng.uniform(0.0, 2.0, n)), rng.integers(0, 64, n), rng.integers(0, 48, n),
                         rng.choice([-1, 1], n))
    frame_times = np.arange(0.0, 2.0, 0.25)
    frames = rng.integers(0, 256, (frame_times.size, 48, 64), dtype=np.uint8)
    t_imu = np.arange(0.0, 2.0, 0.005)
    imu = ImuSamples(t_imu, rng.normal(size=(t_imu.size, 3)), rng.normal(size=(t_imu.size, 3)))
    gt_cam = _random_gt(rng, 30, "camera", extras=False)
    gt_imu = _random_gt(rng, 30, "imu")
    return Sequence("synthetic", camera=cam, events=events, frame_times=frame_times, frames=frames, imu=imu,
                    groundtruth=gt_cam, groundtruth_imu=gt_imu, R_CtoI=Rotation.from_euler("z", 90, degrees=True).as_matrix(),
                    p_CinI=[0.01, 0.02, 0.03], metadata={"imu_noise": {"gyroscope_noise_density": 1e-4}})


# ---------------------------------------------------------------------------------------------- ImuSamples
def test_imu_samples_shapes_and_errors():
    imu = ImuSamples([0.0, 0.1, 0.2], np.zeros((3, 3)), np.ones((3, 3)))
    assert len(imu) == 3 and imu.t.dtype == np.float64 and imu.gyro.shape == (3, 3)
    with pytest.raises(ValueError, match=r"imu.gyro must have shape \(N, 3\); got \(3, 2\)"):
        ImuSamples([0.0, 0.1, 0.2], np.zeros((3, 2)), np.ones((3, 3)))
    with pytest.raises(ValueError, match=r"imu.accel must have shape \(3, 3\) like imu.t; got \(2, 3\)"):
        ImuSamples([0.0, 0.1, 0.2], np.zeros((3, 3)), np.ones((2, 3)))
    with pytest.raises(ValueError, match=r"imu.t must be strictly increasing; got imu.t\[2\] = 0.1"):
        ImuSamples([0.0, 0.1, 0.1], np.zeros((3, 3)), np.ones((3, 3))).validate()
    bad = ImuSamples([0.0, 0.1, 0.2], np.zeros((3, 3)), np.ones((3, 3)))
    bad.accel[1, 2] = np.nan
    with pytest.raises(ValueError, match="imu.accel must be finite; got a non-finite value in row 1"):
        bad.validate()


def test_imu_slice_is_half_open_copy():
    t = np.arange(10) * 0.1
    imu = ImuSamples(t, np.tile(t[:, None], 3), np.zeros((10, 3)))
    part = imu.slice_time(0.2, 0.5)
    np.testing.assert_array_equal(part.t, t[(t >= 0.2) & (t < 0.5)])
    part.gyro[:] = -1.0
    assert imu.gyro.min() == 0.0  # the original is untouched


# ---------------------------------------------------------------------------------------------- GroundTruth
def test_groundtruth_R_BtoG_matches_scipy(rng):
    gt = _random_gt(rng)
    # q_GtoB (JPL) has the same numbers as the Hamilton quaternion of R_BtoG (scipy's convention)
    np.testing.assert_allclose(gt.R_BtoG, Rotation.from_quat(gt.q_GtoB).as_matrix(), atol=1e-12)


def test_groundtruth_interpolate_matches_scipy_slerp_and_linear(rng):
    gt = _random_gt(rng, 15)
    tq = np.sort(rng.uniform(gt.t[0], gt.t[-1], 200))
    out = gt.interpolate(tq)
    expected_R = Slerp(gt.t, Rotation.from_quat(gt.q_GtoB))(tq).as_matrix()
    np.testing.assert_allclose(out.R_BtoG, expected_R, atol=1e-9)
    for axis in range(3):
        np.testing.assert_allclose(out.p_BinG[:, axis], np.interp(tq, gt.t, gt.p_BinG[:, axis]), atol=1e-12)
        np.testing.assert_allclose(out.bias_accel[:, axis], np.interp(tq, gt.t, gt.bias_accel[:, axis]), atol=1e-12)
    assert out.body == "imu" and len(out) == 200
    np.testing.assert_allclose(np.linalg.norm(out.q_GtoB, axis=1), 1.0, atol=1e-12)


def test_groundtruth_interpolate_at_samples_and_sign_flip(rng):
    gt = _random_gt(rng, 5, extras=False)
    gt.q_GtoB[2] *= -1.0  # same rotation, opposite sign: slerp must still take the short way
    at = gt.interpolate(gt.t)
    np.testing.assert_allclose(at.p_BinG, gt.p_BinG, atol=1e-12)
    np.testing.assert_allclose(at.R_BtoG, gt.R_BtoG, atol=1e-9)
    mid = gt.interpolate(0.5 * (gt.t[1] + gt.t[2]))
    expected = Slerp(gt.t[1:3], Rotation.from_quat(gt.q_GtoB[1:3]))([0.5 * (gt.t[1] + gt.t[2])]).as_matrix()
    np.testing.assert_allclose(mid.R_BtoG, expected, atol=1e-9)
    assert mid.v_BinG is None


def test_groundtruth_errors(rng):
    gt = _random_gt(rng, 5)
    with pytest.raises(ValueError, match=r"t must lie within the ground-truth time range"):
        gt.interpolate([gt.t[-1] + 0.01])
    with pytest.raises(ValueError, match=r"body must be one of \('camera', 'imu'\); got 'world'"):
        GroundTruth(gt.t, gt.p_BinG, gt.q_GtoB, body="world")
    with pytest.raises(ValueError, match=r"groundtruth.q_GtoB must have shape \(N, 4\); got \(5, 3\)"):
        GroundTruth(gt.t, gt.p_BinG, gt.q_GtoB[:, :3])
    with pytest.raises(ValueError, match=r"groundtruth.v_BinG must have 5 rows like groundtruth.t; got shape \(4, 3\)"):
        GroundTruth(gt.t, gt.p_BinG, gt.q_GtoB, v_BinG=np.zeros((4, 3)))
    bad = GroundTruth(gt.t, gt.p_BinG, gt.q_GtoB * 1.1)
    with pytest.raises(ValueError, match=r"groundtruth.q_GtoB must hold unit quaternions .* row 0"):
        bad.validate()


# ---------------------------------------------------------------------------------------------- Sequence
def test_sequence_defaults_and_sensor_size():
    seq = Sequence("empty")
    seq.validate()
    assert seq.events.shape == (0,) and seq.frames.shape == (0, 0, 0) and seq.sensor_size is None
    cam = PinholeRadtan.davis240c()
    seq = Sequence("cam", camera=cam)
    assert seq.frames.shape == (0, 180, 240) and seq.sensor_size == (240, 180)
    assert Sequence("f", frames=np.zeros((0, 260, 346), np.uint8)).sensor_size == (346, 260)


def test_sequence_full_validates_and_summary(rng):
    seq = _full_sequence(rng)
    seq.validate()
    text = seq.summary()
    assert "Sequence 'synthetic'" in text and "1,000 over" in text and "64 x 48 px" in text
    assert "400 over" in text and "[imu, v_BinG, bias_gyro, bias_accel]" in text and "imu_noise" in text


def test_sequence_slice_time_matches_masks_and_copies(rng):
    seq = _full_sequence(rng)
    t0, t1 = 0.5, 1.25
    part = seq.slice_time(t0, t1)
    part.validate()
    ev_mask = (seq.events["t"] >= t0) & (seq.events["t"] < t1)
    np.testing.assert_array_equal(part.events, seq.events[ev_mask])
    fr_mask = (seq.frame_times >= t0) & (seq.frame_times < t1)
    np.testing.assert_array_equal(part.frames, seq.frames[fr_mask])
    np.testing.assert_array_equal(part.frame_times, [0.5, 0.75, 1.0])
    np.testing.assert_array_equal(part.imu.t, seq.imu.t[(seq.imu.t >= t0) & (seq.imu.t < t1)])
    gt_mask = (seq.groundtruth_imu.t >= t0) & (seq.groundtruth_imu.t < t1)
    np.testing.assert_array_equal(part.groundtruth_imu.bias_gyro, seq.groundtruth_imu.bias_gyro[gt_mask])
    assert part.camera == seq.camera and part.metadata == seq.metadata and part.metadata is not seq.metadata
    before = seq.events.copy()
    part.events["x"][:] = 0
    part.frames[:] = 0
    np.testing.assert_array_equal(seq.events, before)  # slices are copies: the original is untouched
    with pytest.raises(ValueError, match="t0 and t1 must be finite with t0 <= t1"):
        seq.slice_time(1.0, 0.5)


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda s: setattr(s, "events", make_events([0.0], [64], [0], [1])), r"events: event x out of range \[0, 64\)"),
        (lambda s: setattr(s, "events", np.zeros(3)), r"events must be a 1-D NumPy array of dtype EVENT_DTYPE"),
        (lambda s: setattr(s, "frame_times", s.frame_times[::-1].copy()), r"frame_times must be strictly increasing"),
        (lambda s: setattr(s, "frames", s.frames[:-1]), r"frames must have shape \(8, H, W\) matching frame_times"),
        (lambda s: setattr(s, "frames", s.frames.astype(np.float32)), r"frames must be a uint8 array of shape \(F, H, W\)"),
        (lambda s: setattr(s, "frames", np.zeros((8, 10, 10), np.uint8)), r"frames must have shape \(F, 48, 64\) like the camera"),
        (lambda s: setattr(s.imu, "t", np.zeros_like(s.imu.t)), r"imu.t must be strictly increasing"),
        (lambda s: setattr(s.groundtruth, "body", "imu"), r"groundtruth.body must be 'camera'; got 'imu'"),
        (lambda s: s.groundtruth_imu.p_BinG.__setitem__((3, 1), np.inf), r"groundtruth_imu.p_BinG must be finite; got a non-finite value in row 3"),
        (lambda s: setattr(s, "R_CtoI", 2.0 * np.eye(3)), r"R_CtoI must be a rotation matrix"),
        (lambda s: setattr(s, "p_CinI", np.zeros(2)), r"p_CinI must be a finite vector of shape \(3,\); got shape \(2,\)"),
        (lambda s: setattr(s, "metadata", [1]), r"metadata must be a dict; got list"),
        (lambda s: setattr(s, "imu", "imu"), r"imu must be an ImuSamples or None; got str"),
    ],
)
def test_sequence_validate_names_the_field(rng, change, message):
    seq = _full_sequence(rng)
    with pytest.raises(ValueError, match=message):  # refused on assignment, or by validate() for in-place edits
        change(seq)
        seq.validate()


# ---------------------------------------------------------------------------------------------- construction checks
def _events_like(kind: str):
    """Return a bad `events` argument of the given kind (5 events that would otherwise be fine)."""
    good = make_events([0.0, 0.1, 0.2, 0.3, 0.4], [1, 2, 3, 4, 5], [0, 0, 0, 0, 0], [1, -1, 1, -1, 1])
    columns = np.stack([good["t"], good["x"], good["y"], good["p"]], axis=1)
    if kind == "list":
        return columns.tolist()
    if kind == "n4_float":
        return columns
    if kind == "tuple_of_arrays":
        return (good["t"], good["x"], good["y"], good["p"])
    if kind == "wrong_dtype":
        other = np.zeros(5, dtype=[("t", "<f8"), ("x", "<i4"), ("y", "<i4"), ("p", "<i4")])
        for f in "txyp":
            other[f] = good[f]
        return other
    if kind == "float_1d":
        return good["t"].copy()
    if kind == "2d_structured":
        return good.reshape(5, 1)
    if kind == "unsorted":
        return good[[0, 2, 1, 3, 4]]
    if kind == "nan_time":
        bad = good.copy()
        bad["t"][4] = np.nan
        return bad
    if kind == "zero_polarity":
        bad = good.copy()
        bad["p"][2] = 0
        return bad
    raise AssertionError(kind)


BAD_EVENTS = [
    ("list", r"events must be a 1-D NumPy array of dtype EVENT_DTYPE .* sorted by t; build one with "
             r"evio_lib.events.array.make_events\(t, x, y, p\); got list"),
    ("n4_float", r"got an array of dtype float64 and shape \(5, 4\); for columns \(t, x, y, p\) use make_events\(a\[:, 0\]"),
    ("tuple_of_arrays", r"events must be a 1-D NumPy array of dtype EVENT_DTYPE.*got tuple"),
    ("wrong_dtype", r"got an array of dtype .*'<i4'.* convert with make_events\(ev\['t'\], ev\['x'\]"),
    ("float_1d", r"got an array of dtype float64 and shape \(5,\)$"),
    ("2d_structured", r"got an array of dtype .* and shape \(5, 1\)"),
    ("unsorted", r"events must be sorted by time; found 1 out-of-order timestamps starting at index 2; sort them with "
                 r"events\[np.argsort\(events\['t'\], kind='stable'\)\]"),
    ("nan_time", r"events: event timestamps must be finite; 1 non-finite, first at index 4"),
    ("zero_polarity", r"events: event polarity must be \+1 or -1; 1 events invalid, first at index 2 \(p=0\)"),
]


@pytest.mark.parametrize("kind, message", BAD_EVENTS, ids=[k for k, _ in BAD_EVENTS])
def test_sequence_refuses_bad_events_on_construction_and_assignment(kind, message):
    bad = _events_like(kind)
    before = copy.deepcopy(bad)
    with pytest.raises(ValueError, match=message):
        Sequence("bad", events=bad)
    seq = Sequence("good", events=make_events([0.0, 1.0], [0, 1], [0, 0], [1, 1]))
    kept = seq.events
    with pytest.raises(ValueError, match=message):
        seq.events = bad
    assert seq.events is kept  # the refused value never replaced the good one
    if isinstance(bad, np.ndarray):
        assert bad.tobytes() == before.tobytes() and bad.dtype == before.dtype  # nothing the user gave is modified
    else:
        assert repr(bad) == repr(before)


def test_unsorted_events_can_no_longer_give_wrong_slices():
    """Before the check, searchsorted on unsorted times returned the wrong events without a word."""
    t = np.array([0.0, 0.5, 0.1, 0.6, 0.2])
    unsorted = np.zeros(5, EVENT_DTYPE)
    unsorted["t"], unsorted["x"], unsorted["p"] = t, np.arange(5), 1
    truth = np.flatnonzero((t >= 0.0) & (t < 0.3))  # indices 0, 2, 4 lie in [0, 0.3)
    wrong = np.arange(5)[slice(*np.searchsorted(t, [0.0, 0.3]))]
    assert sorted(wrong.tolist()) != truth.tolist()  # the silent failure the construction check prevents
    with pytest.raises(ValueError, match="events must be sorted by time"):
        Sequence("unsorted", events=unsorted)
    order = np.argsort(unsorted["t"], kind="stable")  # the conversion the message suggests
    seq = Sequence("sorted", events=unsorted[order])
    assert sorted(seq.slice_time(0.0, 0.3).events["x"].tolist()) == truth.tolist()
    assert sorted(events_between(seq.events, 0.0, 0.3)["x"].tolist()) == truth.tolist()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"R_CtoI": np.eye(2)}, r"R_CtoI must be a finite \(3, 3\) rotation matrix; got shape \(2, 2\)"),
        ({"R_CtoI": np.eye(3).ravel()}, r"R_CtoI must be a finite \(3, 3\) rotation matrix; got shape \(9,\)"),
        ({"R_CtoI": np.diag([1.0, 1.0, -1.0])}, r"R_CtoI must be a rotation matrix \(R R\^T = I, det 1.*got det -1"),
        ({"R_CtoI": 2.0 * np.eye(3)}, r"R_CtoI must be a rotation matrix"),
        ({"R_CtoI": np.full((3, 3), np.nan)}, r"R_CtoI must be a finite \(3, 3\) rotation matrix"),
        ({"R_CtoI": "identity"}, r"R_CtoI must be a \(3, 3\) rotation matrix; got 'identity'"),
        ({"p_CinI": [0.0, 0.1]}, r"p_CinI must be a finite vector of shape \(3,\); got shape \(2,\)"),
        ({"p_CinI": np.zeros((3, 1))}, r"p_CinI must be a finite vector of shape \(3,\); got shape \(3, 1\)"),
        ({"p_CinI": [0.0, np.inf, 0.0]}, r"p_CinI must be a finite vector of shape \(3,\)"),
        ({"p_CinI": "abc"}, r"p_CinI must be a vector of shape \(3,\) \[m\]; got 'abc'"),
        ({"frame_times": [0.0, 0.2, 0.1], "frames": np.zeros((3, 4, 5), np.uint8)}, r"frame_times must be strictly increasing"),
        ({"frame_times": np.zeros((2, 1))}, r"frame_times must have shape \(F,\); got \(2, 1\)"),
        ({"frame_times": [0.0, 0.1], "frames": np.zeros((3, 4, 5), np.uint8)},
         r"frames must have shape \(2, H, W\) matching frame_times \(2,\); got \(3, 4, 5\)"),
        ({"frame_times": [0.0], "frames": np.zeros((1, 4, 5), np.float32)},
         r"frames must be a uint8 array of shape \(F, H, W\) \(convert float images .*to_uint8_image\); got dtype float32"),
        ({"frame_times": [0.0], "frames": [[[0]]]}, r"frames must be a uint8 array .*; got list"),
        ({"camera": PinholeRadtan.davis240c(), "frame_times": [0.0], "frames": np.zeros((1, 4, 5), np.uint8)},
         r"frames must have shape \(F, 180, 240\) like the camera; got \(1, 4, 5\)"),
        ({"camera": "davis240c"}, r"camera must be a PinholeRadtan or None; got str"),
        ({"imu": ImuSamples([0.0, 0.2, 0.1], np.zeros((3, 3)), np.zeros((3, 3)))}, r"imu.t must be strictly increasing"),
        ({"imu": {"t": [0.0]}}, r"imu must be an ImuSamples or None; got dict"),
        ({"groundtruth": GroundTruth([0.0, 1.0], np.zeros((2, 3)), [[0, 0, 0, 1]] * 2, body="imu")},
         r"groundtruth.body must be 'camera'; got 'imu'"),
        ({"groundtruth_imu": GroundTruth([1.0, 0.0], np.zeros((2, 3)), [[0, 0, 0, 1]] * 2, body="imu")},
         r"groundtruth_imu.t must be strictly increasing"),
        ({"metadata": [("a", 1)]}, r"metadata must be a dict; got list"),
    ],
)
def test_sequence_construction_checks_fields(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Sequence(kwargs.pop("name", "bad"), **kwargs)


def test_sequence_name_must_be_str():
    with pytest.raises(ValueError, match="name must be a str; got int"):
        Sequence(3)


def test_sequence_construction_accepts_lists_for_extrinsics_and_keeps_inputs(rng):
    R = Rotation.from_euler("xyz", [10, 20, 30], degrees=True).as_matrix()
    p = [0.01, 0.02, 0.03]
    events = make_events([0.0, 0.1], [1, 2], [3, 4], [1, -1])
    seq = Sequence("lists", events=events, R_CtoI=R.tolist(), p_CinI=p)
    assert seq.R_CtoI.shape == (3, 3) and seq.p_CinI.dtype == np.float64
    assert seq.events is events and p == [0.01, 0.02, 0.03]
    seq.validate()


def test_slice_time_refuses_times_edited_out_of_order(rng):
    seq = _full_sequence(rng)
    seq.imu.t[:] = seq.imu.t[::-1].copy()  # an in-place edit that no assignment check can see
    with pytest.raises(ValueError, match=r"imu.t must be sorted by time to slice it"):
        seq.slice_time(0.5, 1.0)
    with pytest.raises(ValueError, match=r"imu.t must be strictly increasing"):
        seq.validate()
    gt = _random_gt(rng, 6)
    gt.t[:] = gt.t[::-1].copy()
    with pytest.raises(ValueError, match=r"groundtruth.t must be sorted by time to slice it"):
        gt.slice_time(0.0, 1.0)


def test_non_unit_quaternions_are_left_to_validate(rng):
    """Construction checks order and finiteness; the unit norm is validate()'s (readers normalise, see io.tum)."""
    gt = _random_gt(rng, 5)
    seq = Sequence("q", groundtruth_imu=GroundTruth(gt.t, gt.p_BinG, gt.q_GtoB * 2.0, body="imu"))
    with pytest.raises(ValueError, match=r"groundtruth_imu.q_GtoB must hold unit quaternions"):
        seq.validate()
