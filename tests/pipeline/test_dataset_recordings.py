"""A simulated recording written as an ECD folder, a ROS bag and an MVSEC-layout HDF5 file runs to the same
trajectory, bit for bit (APS frames with SIFT, and motion-compensated event frames read from disk a window at a
time with KLT)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("rosbags")
pytest.importorskip("h5py")

from evio_lib.io.aedat4 import us_to_seconds  # noqa: E402
from evio_lib.io.ecd import SIDECAR_NAME, write_ecd  # noqa: E402
from evio_lib.io.hdf5 import pose_matrices_to_groundtruth, write_mvsec_h5  # noqa: E402
from evio_lib.io.rosbag import write_rosbag  # noqa: E402
from evio_lib.pipeline.dataset import load_dataset  # noqa: E402
from evio_lib.pipeline.run import PipelineConfig, run_pipeline  # noqa: E402
from evio_lib.sequence import GroundTruth, ImuSamples  # noqa: E402

T_SHIFT_US = 1_500_000_000_000_000  # the files carry Unix times, as recorded ones do


def _on_us_grid(t: np.ndarray) -> np.ndarray:
    """Times moved to Unix time and put on the microsecond grid both files store exactly."""
    return us_to_seconds(np.round(np.asarray(t) * 1e6).astype(np.int64) + T_SHIFT_US)


def _matrices(gt: GroundTruth) -> np.ndarray:
    from evio_lib.geometry.rotation import quat_to_rot

    T = np.tile(np.eye(4), (len(gt), 1, 1))
    T[:, :3, :3] = np.swapaxes(quat_to_rot(gt.q_GtoB), -1, -2)
    T[:, :3, 3] = gt.p_BinG
    return T


@pytest.fixture(scope="module")
def recordings(boxes_events, tmp_path_factory):
    """(folder, {name: (ECD folder, recording file)}, extrinsics YAML): one simulated stretch in each container."""
    import yaml

    folder = tmp_path_factory.mktemp("recordings")
    sim = boxes_events.sequence
    events = sim.events.copy()
    events["t"] = _on_us_grid(events["t"])
    gt = sim.groundtruth
    base = dataclasses.replace(
        sim, events=events, frame_times=_on_us_grid(sim.frame_times),
        imu=ImuSamples(t=_on_us_grid(sim.imu.t), gyro=sim.imu.gyro, accel=sim.imu.accel),
        groundtruth=GroundTruth(t=_on_us_grid(gt.t), p_BinG=gt.p_BinG, q_GtoB=gt.q_GtoB, body="camera"),
        groundtruth_imu=None, R_CtoI=None, p_CinI=None, metadata={})
    # MVSEC stores camera-to-world matrices: its quaternions are rot_to_quat of them
    matrices = _matrices(base.groundtruth)
    h5_truth = pose_matrices_to_groundtruth(base.groundtruth.t, matrices)
    h5_base = dataclasses.replace(base, groundtruth=h5_truth)
    T_cam_imu = np.eye(4)
    T_cam_imu[:3, :3] = np.asarray(sim.R_CtoI).T
    T_cam_imu[:3, 3] = -np.asarray(sim.R_CtoI).T @ np.asarray(sim.p_CinI)
    extrinsics = folder / "camchain.yaml"
    extrinsics.write_text(yaml.safe_dump({"cam0": {"T_cam_imu": T_cam_imu.tolist()}}))
    calib = folder / "calib.txt"
    c = sim.camera
    calib.write_text(" ".join(repr(float(v)) for v in (c.fx, c.fy, c.cx, c.cy, c.k1, c.k2, c.p1, c.p2, c.k3)) + "\n")
    pairs = {}
    for name, seq in (("bag", base), ("h5", h5_base)):
        ecd = write_ecd(seq, folder / f"boxes_like_{name}_ecd")
        (ecd / SIDECAR_NAME).unlink()  # what the other containers hold: no extrinsics, no noise model, no metadata
        if name == "bag":
            pairs[name] = (ecd, write_rosbag(seq, folder / "boxes_like.bag", events_per_message=5000))
        else:
            pairs[name] = (ecd, write_mvsec_h5(seq, folder / "boxes_like_data.hdf5", pose_matrices=matrices))
    return folder, pairs, extrinsics, calib


@pytest.mark.parametrize("container", ["bag", "h5"])
@pytest.mark.parametrize("config", [dict(frames="aps", features="sift"),
                                    dict(frames="mc-events", tracker="klt", features="fast")],
                         ids=["aps-sift", "mc-events-klt"])
def test_bag_and_h5_run_like_their_ecd_folder_bit_for_bit(recordings, container, config, monkeypatch):
    from evio_lib.io import event_source

    monkeypatch.setattr(event_source.EventSource, "chunk_events", 3001)  # window cuts across many blocks
    monkeypatch.setattr(event_source, "INDEX_STRIDE", 257)
    _, pairs, extrinsics, calib = recordings
    ecd, recording = pairs[container]
    need_events = config["frames"] != "aps"
    runs = []
    for source in (ecd, recording):
        data = load_dataset(source, need_events=need_events, need_frames=not need_events, extrinsics=extrinsics,
                            calib=calib if source == recording and container == "h5" else None)
        if source == recording and need_events:
            assert isinstance(data.sequence.events, np.memmap)  # read a window at a time from disk
        runs.append(run_pipeline(data, PipelineConfig(max_duration=1.2, **config)))
    ecd_run, file_run = runs
    assert len(ecd_run.t) > 5
    for name in ("t", "q_GtoI", "p_IinG", "v_IinG", "b_g", "b_a", "sigma"):
        assert getattr(file_run, name).tobytes() == getattr(ecd_run, name).tobytes(), name


def test_recordings_need_calibration_and_say_their_topics(recordings):
    _, pairs, extrinsics, calib = recordings
    with pytest.raises(ValueError, match=r"boxes_like_data.hdf5: no calibration in the file; give one with --calib"):
        load_dataset(pairs["h5"][1], extrinsics=extrinsics)
    data = load_dataset(pairs["bag"][1])
    assert data.kind == "rosbag"
    assert any(note.startswith("topics: events /dvs/events, frames /dvs/image_raw, imu /dvs/imu") for note in data.notes)
    with pytest.raises(ValueError, match="--topics applies to ROS bags and MVSEC HDF5 files"):
        load_dataset(pairs["bag"][0], topics="ecd")
