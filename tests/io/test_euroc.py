"""Tests of evio_lib.io.euroc: the EuRoC ASL layout (real micro slice, synthetic folders, errors, yaml parser)."""
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.io.errors import DataFileError
from evio_lib.io.euroc import ns_to_seconds, read_asl_yaml, read_euroc

EUROC = "euroc_V1_01_easy_micro"
IMU_HEADER = "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n"
CAM_YAML = """%YAML:1.0
sensor_type: camera
T_BS:
  cols: 4
  rows: 4
  data: [0.0, -1.0, 0.0, 0.1,
         1.0, 0.0, 0.0, 0.2,
         0.0, 0.0, 1.0, 0.3,
         0.0, 0.0, 0.0, 1.0]
rate_hz: 20
resolution: [16, 12]
camera_model: pinhole
intrinsics: [10.0, 11.0, 7.5, 5.5] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [-0.1, 0.01, 0.001, 0.002]
"""
IMU_YAML = """%YAML:1.0
T_BS:
  cols: 4
  rows: 4
  data: [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
rate_hz: 200
gyroscope_noise_density: 1.6968e-04     # [ rad / s / sqrt(Hz) ]
accelerometer_noise_density: 2.0000e-3  # [ m / s^2 / sqrt(Hz) ]
"""


def _euroc_folder(tmp_path, imu_rows=None, cam_rows=None, gt_rows=None, cam_yaml=CAM_YAML):
    root = tmp_path / "seq"
    (root / "mav0" / "imu0").mkdir(parents=True)
    (root / "mav0" / "cam0" / "data").mkdir(parents=True)
    if imu_rows is None:
        imu_rows = [f"{1000000000 + i * 5000000},0.01,0.02,0.03,0.0,0.0,9.81" for i in range(4)]
    (root / "mav0" / "imu0" / "data.csv").write_text(IMU_HEADER + "\n".join(imu_rows) + "\n")
    (root / "mav0" / "imu0" / "sensor.yaml").write_text(IMU_YAML)
    (root / "mav0" / "cam0" / "sensor.yaml").write_text(cam_yaml)
    if cam_rows is None:
        cam_rows = [f"{1000000000 + i * 50000000},{1000000000 + i * 50000000}.png" for i in range(2)]
    for i, row in enumerate(cam_rows):
        name = row.split(",")[1]
        cv2.imwrite(str(root / "mav0" / "cam0" / "data" / name), np.full((12, 16), 10 * i, np.uint8))
    (root / "mav0" / "cam0" / "data.csv").write_text("#timestamp [ns],filename\n" + "\n".join(cam_rows) + "\n")
    if gt_rows is not None:
        gt = root / "mav0" / "state_groundtruth_estimate0"
        gt.mkdir()
        (gt / "data.csv").write_text("#timestamp,p_x,p_y,p_z,q_w,q_x,q_y,q_z,v_x,v_y,v_z,bw_x,bw_y,bw_z,ba_x,ba_y,ba_z\n"
                                     + "\n".join(gt_rows) + "\n")
    return root


def test_ns_to_seconds_is_correctly_rounded():
    ns = np.array([1403715273262142976, 1403715418857143040, 5, 0], dtype=np.int64)
    expected = [float(int(v) / 10**9) for v in ns]  # Python's int / int is correctly rounded
    np.testing.assert_array_equal(ns_to_seconds(ns), expected)


def test_synthetic_folder_values_and_extrinsics(tmp_path):
    q_wxyz = Rotation.from_euler("x", 30, degrees=True).as_quat(scalar_first=True)
    gt_rows = [f"{1000000000 + i * 5000000},1,2,3,{','.join(map(repr, q_wxyz.tolist()))},0.1,0.2,0.3,0.01,0.02,0.03,0.4,0.5,0.6"
               for i in range(3)]
    seq = read_euroc(_euroc_folder(tmp_path, gt_rows=gt_rows))
    seq.validate()
    np.testing.assert_array_equal(seq.imu.t, [1.0, 1.005, 1.01, 1.015])
    np.testing.assert_array_equal(seq.imu.gyro[0], [0.01, 0.02, 0.03])  # w first, then a
    np.testing.assert_array_equal(seq.imu.accel[0], [0.0, 0.0, 9.81])
    assert seq.camera.fx == 10.0 and seq.camera.cy == 5.5 and seq.camera.p2 == 0.002 and seq.camera.width == 16
    np.testing.assert_array_equal(seq.frames[1], np.full((12, 16), 10, np.uint8))
    np.testing.assert_array_equal(seq.frame_times, [1.0, 1.05])
    np.testing.assert_array_equal(seq.R_CtoI, [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    np.testing.assert_array_equal(seq.p_CinI, [0.1, 0.2, 0.3])
    gt = seq.groundtruth_imu
    np.testing.assert_allclose(gt.R_BtoG[0], Rotation.from_euler("x", 30, degrees=True).as_matrix(), atol=1e-12)
    np.testing.assert_array_equal(gt.bias_accel[0], [0.4, 0.5, 0.6])
    np.testing.assert_array_equal(gt.v_BinG[0], [0.1, 0.2, 0.3])
    # camera pose = IMU pose composed with the extrinsics (independent: 4x4 matrices)
    T_GI = np.eye(4)
    T_GI[:3, :3], T_GI[:3, 3] = gt.R_BtoG[0], gt.p_BinG[0]
    T_IC = np.eye(4)
    T_IC[:3, :3], T_IC[:3, 3] = seq.R_CtoI, seq.p_CinI
    T_GC = T_GI @ T_IC
    np.testing.assert_allclose(seq.groundtruth.R_BtoG[0], T_GC[:3, :3], atol=1e-12)
    np.testing.assert_allclose(seq.groundtruth.p_BinG[0], T_GC[:3, 3], atol=1e-12)
    assert seq.metadata["imu_noise"] == {"gyroscope_noise_density": 1.6968e-4, "accelerometer_noise_density": 2.0e-3}
    assert read_euroc(_euroc_folder(tmp_path / "b"), load_frames=False).frames.shape == (0, 12, 16)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"imu_rows": ["1000000000,0,0,0,0,0,9.81", "1005000000,0,0,0,0,9.81"]},
         r"mav0/imu0/data.csv line 3: expected 7 columns \(t_ns wx wy wz ax ay az\), got 6"),
        ({"imu_rows": ["1000000000.5,0,0,0,0,0,9.81"]}, r"mav0/imu0/data.csv line 2: column 't_ns' must be an integer; got '1000000000.5'"),
        ({"imu_rows": ["1000000000,0,0,0,0,0,9.81", "1000000000,0,0,0,0,0,9.81"]},
         r"mav0/imu0/data.csv line 3: timestamp 1000000000 follows 1000000000 .*no duplicates"),
        ({"imu_rows": ["1000000000,0,0,0,0,0,9.81", "1005000000,0,0,nan,0,0,9.81"]},
         r"mav0/imu0/data.csv line 3: column 'wz' must be a finite number"),
        ({"cam_rows": ["1000000000,a.png", "900000000,b.png"]}, r"mav0/cam0/data.csv line 3: timestamp 900000000 follows 1000000000"),
        ({"cam_rows": ["1000000000,a.png,x"]}, r"mav0/cam0/data.csv line 2: expected 2 columns \(timestamp \[ns\], filename\), got 3"),
        ({"gt_rows": ["1000000000,1,2,3,1,0,0,0,0,0,0,0,0,0,0,0"]},
         r"mav0/state_groundtruth_estimate0/data.csv line 2: expected 17 columns"),
        ({"gt_rows": ["1000000000,1,2,3,0,0,0,0,0,0,0,0,0,0,0,0,0"]},
         r"mav0/state_groundtruth_estimate0/data.csv line 2: quaternion \(qw qx qy qz\) has zero norm"),
        ({"cam_yaml": CAM_YAML.replace("radial-tangential", "equidistant")},
         r"mav0/cam0/sensor.yaml: only camera_model 'pinhole' with distortion_model 'radial-tangential' is supported"),
        ({"cam_yaml": CAM_YAML.replace("0.0, 0.0, 0.0, 1.0]", "0.0, 0.0, 0.0, 1.0")},
         r"mav0/cam0/sensor.yaml line 6: flow list of 'data' is not closed"),
        ({"cam_yaml": CAM_YAML.replace("resolution: [16, 12]", "resolution: [16]")},
         r"mav0/cam0/sensor.yaml: resolution must be \[width, height\]; got \[16\]"),
        ({"cam_yaml": CAM_YAML.replace("resolution: [16, 12]", "resolution: [20, 12]")},
         r"differs from the resolution 20 x 12 in mav0/cam0/sensor.yaml"),
        ({"cam_yaml": CAM_YAML.replace("resolution: [16, 12]", "resolution: [16, big]")},
         r"mav0/cam0/sensor.yaml: resolution must be whole numbers of pixels \[width, height\]; got \[16, 'big'\] "
         r"\('big' is not\)"),
        ({"cam_yaml": CAM_YAML.replace("resolution: [16, 12]", "resolution: [16.5, 12]")},
         r"mav0/cam0/sensor.yaml: resolution must be whole numbers of pixels"),
    ],
)
def test_errors_name_file_line_problem(tmp_path, kwargs, message):
    with pytest.raises(DataFileError, match=message):
        read_euroc(_euroc_folder(tmp_path, **kwargs))


def test_missing_files(tmp_path):
    with pytest.raises(DataFileError, match="EuRoC folder not found"):
        read_euroc(tmp_path)
    root = _euroc_folder(tmp_path)
    (root / "mav0" / "cam0" / "data" / "1000000000.png").unlink()
    with pytest.raises(DataFileError, match=r"mav0/cam0/data.csv line 2: image file data/1000000000.png not found"):
        read_euroc(root)
    (root / "mav0" / "imu0" / "data.csv").unlink()
    with pytest.raises(DataFileError, match=r"data.csv: file not found at .*imu0/data.csv"):
        read_euroc(root)


def test_yaml_parser_matches_pyyaml(real_data_dir):
    yaml = pytest.importorskip("yaml")
    for sensor in ("cam0", "imu0", "state_groundtruth_estimate0"):
        path = real_data_dir / EUROC / "mav0" / sensor / "sensor.yaml"
        text = "\n".join(line for line in path.read_text().splitlines() if not line.startswith("%"))
        assert read_asl_yaml(path) == yaml.safe_load(text), sensor


def test_real_micro_slice(real_data_dir):
    seq = read_euroc(real_data_dir / EUROC)
    seq.validate()
    # images: 95 frames 752 x 480 at 20 Hz over 4.7 s
    assert seq.frames.shape == (95, 480, 752) and seq.frames.dtype == np.uint8
    assert seq.frame_times[0] == pytest.approx(1403715273.262143) and seq.frame_times[-1] == pytest.approx(1403715277.962143)
    assert np.diff(seq.frame_times).mean() == pytest.approx(0.05, abs=1e-6)
    first = cv2.imread(str(real_data_dir / EUROC / "mav0/cam0/data/1403715273262142976.png"), cv2.IMREAD_GRAYSCALE)
    np.testing.assert_array_equal(seq.frames[0], first)
    # IMU: 29,120 samples at 200 Hz over 145.6 s, first row as in the file
    assert len(seq.imu) == 29120 and seq.imu.t[-1] == pytest.approx(1403715418.857143)
    np.testing.assert_array_equal(seq.imu.gyro[0], [-0.0020943951023931952, 0.017453292519943295, 0.07749261878854824])
    np.testing.assert_array_equal(seq.imu.accel[0], [9.0874956666666655, 0.13075533333333333, -3.6938381666666662])
    # the MAV is still during the images: |a| ~ 9.81
    still = seq.imu.t < seq.frame_times[-1]
    assert np.linalg.norm(seq.imu.accel[still], axis=1).mean() == pytest.approx(9.81, abs=0.1)
    # calibration and noise
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy) == (458.654, 457.296, 367.215, 248.375)
    assert (seq.camera.k1, seq.camera.p2, seq.camera.k3) == (-0.28340811, 1.76187114e-05, 0.0)
    np.testing.assert_allclose(seq.R_CtoI @ seq.R_CtoI.T, np.eye(3), atol=1e-6)
    np.testing.assert_array_equal(seq.p_CinI, [-0.0216401454975, -0.064676986768, 0.00981073058949])
    assert seq.metadata["imu_noise"]["gyroscope_random_walk"] == 1.9393e-05
    assert seq.metadata["imu_noise"]["accelerometer_noise_density"] == 2.0e-3
    # ground truth (open_vins, 2,895 poses with biases)
    gt = seq.groundtruth_imu
    assert len(gt) == 2895 and gt.bias_gyro is not None and gt.bias_accel is not None and gt.v_BinG is not None
    np.testing.assert_array_equal(gt.bias_gyro[0], [-0.00224703, 0.0215352, 0.0770299])
    np.testing.assert_array_equal(gt.bias_accel[0], [-0.0180115, 0.0659796, 0.0309774])
    R_file = Rotation.from_quat([-0.824237, -0.106942, -0.551702, 0.069433]).as_matrix()  # body -> world
    np.testing.assert_allclose(gt.R_BtoG[0], R_file / np.cbrt(np.linalg.det(R_file)), atol=1e-5)
    assert seq.metadata["groundtruth_file"] == "groundtruth_openvins/V1_01_easy.csv"


def test_real_gravity_and_gyro_bias_in_ground_truth_frame(real_data_dir):
    """Physics check of the conventions: while still, R_ItoG (a - b_a) = +g_up and w - b_w = 0."""
    seq = read_euroc(real_data_dir / EUROC, load_frames=False)
    gt = seq.groundtruth_imu.interpolate(seq.imu.t[(seq.imu.t > 1403715273.3) & (seq.imu.t < 1403715277.9)])
    sel = np.isin(seq.imu.t, gt.t)
    specific_force_G = np.einsum("nij,nj->ni", gt.R_BtoG, seq.imu.accel[sel] - gt.bias_accel)
    np.testing.assert_allclose(specific_force_G.mean(axis=0), [0.0, 0.0, 9.81], atol=0.05)
    np.testing.assert_allclose((seq.imu.gyro[sel] - gt.bias_gyro).mean(axis=0), 0.0, atol=2e-3)
    # the camera ground truth is the IMU one moved by the extrinsics: the optical axis of cam0 is nearly horizontal
    z_C_in_G = seq.groundtruth.R_BtoG[0][:, 2]
    assert abs(z_C_in_G[2]) < 0.5
    np.testing.assert_allclose(seq.groundtruth.p_BinG[0] - seq.groundtruth_imu.p_BinG[0],
                               seq.groundtruth_imu.R_BtoG[0] @ seq.p_CinI, atol=1e-12)


# ---------------------------------------------------------------------------------------------- bad recordings (issue 17)
def _imu_rows(start, step, n=4):
    return [f"{start + i * step},0.01,0.02,0.03,0.0,0.0,9.81" for i in range(n)]


def _gt_rows(start, step, q_wxyz=(1.0, 0.0, 0.0, 0.0), n=3):
    return [f"{start + i * step},1,2,3,{','.join(map(repr, q_wxyz))},0,0,0,0,0,0,0,0,0" for i in range(n)]


BAD_FOLDERS = [
    ("imu_microseconds", {"imu_rows": _imu_rows(1_000_000, 5_000)},
     r"mav0/imu0/data.csv: the median step between timestamps is 5000, i.e. 5e-06 s \(2e\+05 Hz\) read as nanoseconds, "
     r"outside a plausible IMU rate of 10 Hz .. 10000 Hz; EuRoC timestamps must be integer nanoseconds .*"
     r"they look like microseconds \(multiply by 1e\+03"),
    ("imu_milliseconds", {"imu_rows": _imu_rows(1_000, 5)}, r"read as nanoseconds.*they look like milliseconds"),
    ("imu_too_slow", {"imu_rows": _imu_rows(1_000_000_000, 1_000_000_000)}, r"1 s \(1 Hz\) read as nanoseconds"),
    ("imu_header_only", {"imu_rows": []},
     r"mav0/imu0/data.csv: no IMU samples \(only comments or a header\); expected at least 2 lines `timestamp \[ns\]"),
    ("imu_single_sample", {"imu_rows": _imu_rows(1_000_000_000, 5_000_000, n=1)}, r"mav0/imu0/data.csv: a single IMU sample"),
    ("gt_microseconds", {"gt_rows": _gt_rows(1_000_000, 5_000)},
     r"mav0/state_groundtruth_estimate0/data.csv: its times \(0.001 .. 0.00101 s\) and those of mav0/imu0/data.csv "
     r"\(1 .. 1.015 s\) differ by a factor of 1002: mav0/state_groundtruth_estimate0/data.csv looks like microseconds"),
    ("cam_microseconds", {"cam_rows": ["1000000,1000000.png", "1050000,1050000.png"]},
     r"mav0/cam0/data.csv: its times .* differ by a factor of 982.9: mav0/cam0/data.csv looks like microseconds"),
    ("gt_quaternion_norm_2", {"gt_rows": _gt_rows(1_000_000_000, 5_000_000, (2.0, 0.0, 0.0, 0.0))},
     r"mav0/state_groundtruth_estimate0/data.csv line 2: quaternion \(qw qx qy qz\) has norm 2; expected a unit quaternion"),
    ("gt_quaternion_norm_half", {"gt_rows": _gt_rows(1_000_000_000, 5_000_000, (0.5, 0.0, 0.0, 0.0))},
     r"data.csv line 2: quaternion \(qw qx qy qz\) has norm 0.5; expected a unit quaternion"),
]


@pytest.mark.parametrize("kwargs, message", [b[1:] for b in BAD_FOLDERS], ids=[b[0] for b in BAD_FOLDERS])
def test_bad_recordings_are_clear_errors(tmp_path, kwargs, message):
    root = _euroc_folder(tmp_path, **kwargs)
    before = {p: p.read_bytes() for p in root.rglob("*") if p.is_file()}
    with pytest.raises(DataFileError, match=message):
        read_euroc(root)
    assert {p: p.read_bytes() for p in root.rglob("*") if p.is_file()} == before  # the reader never writes


def test_missing_camera_index_is_an_error_unless_frames_are_skipped(tmp_path):
    root = _euroc_folder(tmp_path)
    (root / "mav0" / "cam0" / "data.csv").unlink()
    with pytest.raises(DataFileError, match=r"mav0/cam0/data.csv: file not found, although the camera folder mav0/cam0/ "
                                            r"exists .*the frames are what features are tracked on"):
        read_euroc(root)
    seq = read_euroc(root, load_frames=False)  # the calibration is still there
    assert seq.camera.width == 16 and len(seq.frame_times) == 0


def test_named_camera_must_exist(tmp_path):
    root = _euroc_folder(tmp_path)
    with pytest.raises(DataFileError, match=r"camera 'cam1' not found: .*mav0 has no folder cam1/ \(camera folders: cam0\)"):
        read_euroc(root, camera="cam1")
    for bad in ("", 3, "../cam0"):
        with pytest.raises(ValueError, match=r"camera must be the name of a camera folder such as 'cam0'"):
            read_euroc(root, camera=bad)
    # a second camera, when present, is read by name
    import shutil

    shutil.copytree(root / "mav0" / "cam0", root / "mav0" / "cam1")
    seq = read_euroc(root, camera="cam1")
    assert seq.metadata["camera_name"] == "cam1" and seq.frames.shape == (2, 12, 16)


def test_recording_without_camera_loads_and_says_so(tmp_path):
    import shutil

    root = _euroc_folder(tmp_path, gt_rows=_gt_rows(1_000_000_000, 5_000_000))
    shutil.rmtree(root / "mav0" / "cam0")
    with pytest.warns(UserWarning, match=r"no camera folder mav0/cam0 \(camera folders: none\); loading IMU and ground truth only"):
        seq = read_euroc(root)
    assert seq.camera is None and seq.frames.shape == (0, 0, 0) and seq.metadata["camera_name"] is None
    assert len(seq.imu) == 4 and len(seq.groundtruth_imu) == 3 and seq.groundtruth is None  # no extrinsics: no camera poses
    seq.validate()
    with pytest.raises(DataFileError, match=r"camera 'cam0' not found: .*\(camera folders: none\)"):
        read_euroc(root, camera="cam0")  # asked for by name: an error, not a warning


def test_near_unit_groundtruth_quaternions_are_normalised(tmp_path):
    q = np.array([0.9, 0.3, 0.2, 0.1])
    q_file = q / np.linalg.norm(q) * 1.0008  # few decimals in a file: norm off by 8e-4 (< 1e-3)
    seq = read_euroc(_euroc_folder(tmp_path, gt_rows=_gt_rows(1_000_000_000, 5_000_000, tuple(q_file.tolist()))))
    seq.validate()
    q_xyzw = np.array([q[1], q[2], q[3], q[0]]) / np.linalg.norm(q)
    np.testing.assert_allclose(seq.groundtruth_imu.q_GtoB[0], q_xyzw, atol=1e-15)
    np.testing.assert_allclose(seq.groundtruth_imu.R_BtoG[0], Rotation.from_quat(q_xyzw).as_matrix(), atol=1e-12)


def test_real_imu_in_microseconds_is_refused(real_data_dir, tmp_path):
    """The real IMU file rewritten in microseconds (a likely export mistake): refused, with the unit named."""
    lines = (real_data_dir / EUROC / "mav0" / "imu0" / "data.csv").read_text().splitlines()
    rows = [lines[0]] + [f"{int(l.split(',', 1)[0]) // 1000},{l.split(',', 1)[1]}" for l in lines[1:2001]]
    (tmp_path / "mav0" / "imu0").mkdir(parents=True)
    (tmp_path / "mav0" / "imu0" / "data.csv").write_text("\n".join(rows) + "\n")
    with pytest.warns(UserWarning, match="no camera folder"):
        with pytest.raises(DataFileError, match=r"imu0/data.csv: .*\(2e\+05 Hz\) read as nanoseconds.*look like microseconds"):
            read_euroc(tmp_path)
    # the ground truth given with nanosecond IMU but microsecond ground truth: the time bases disagree by 1000
    ns_rows = lines[: 2001]
    (tmp_path / "mav0" / "imu0" / "data.csv").write_text("\n".join(ns_rows) + "\n")
    gt_lines = (real_data_dir / EUROC / "groundtruth_openvins" / "V1_01_easy.csv").read_text().splitlines()
    gt_us = [l if l.startswith("#") else f"{int(l.split(',', 1)[0]) // 1000},{l.split(',', 1)[1]}" for l in gt_lines[:200]]
    (tmp_path / "gt_us.csv").write_text("\n".join(gt_us) + "\n")
    with pytest.warns(UserWarning, match="no camera folder"):
        with pytest.raises(DataFileError, match=r"gt_us.csv: .*differ by a factor of \d+(\.\d+)?: gt_us.csv looks like microseconds"):
            read_euroc(tmp_path, groundtruth=tmp_path / "gt_us.csv")


def test_real_slice_camera_names(real_data_dir):
    with pytest.raises(DataFileError, match=r"camera 'cam1' not found: .* \(camera folders: cam0\)"):
        read_euroc(real_data_dir / EUROC, camera="cam1", load_frames=False)
    seq = read_euroc(real_data_dir / EUROC, camera="cam0", load_frames=False)
    assert seq.metadata["camera_name"] == "cam0" and seq.camera.width == 752


def test_camera_without_calibration_loads_frames_and_says_so(tmp_path):
    root = _euroc_folder(tmp_path)
    (root / "mav0" / "cam0" / "sensor.yaml").unlink()
    with pytest.warns(UserWarning, match=r"mav0/cam0/sensor.yaml not found: cam0 has no calibration \(camera=None, no extrinsics\)"):
        seq = read_euroc(root)
    assert seq.camera is None and seq.R_CtoI is None and seq.frames.shape == (2, 12, 16)
    seq.validate()


@pytest.mark.parametrize("relative", ["mav0/cam0/sensor.yaml", "mav0/cam0/data.csv", "mav0/imu0/data.csv"])
def test_files_that_are_not_utf8_text_are_named_with_their_line(tmp_path, relative):
    root = _euroc_folder(tmp_path)
    path = root / relative
    lines = path.read_bytes().split(b"\n")
    lines[2] = lines[2] + b" \xe9"
    path.write_bytes(b"\n".join(lines))
    with pytest.raises(DataFileError, match=r"line 3") as error:
        read_euroc(root)
    assert "codec" not in str(error.value) and Path(relative).name in str(error.value)


def test_a_damaged_frame_is_one_error_with_the_decoders_words_and_nothing_on_stderr(tmp_path, capfd):
    root = _euroc_folder(tmp_path)
    image = next((root / "mav0" / "cam0" / "data").iterdir())
    png = bytearray(image.read_bytes())
    png[20] ^= 0xFF
    image.write_bytes(bytes(png))
    with pytest.raises(DataFileError, match=rf"{image.name}: could not decode the image \(libpng error: IHDR: CRC"):
        read_euroc(root)
    assert capfd.readouterr().err == ""
