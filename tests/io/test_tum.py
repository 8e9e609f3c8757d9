"""Tests of evio_lib.io.tum: TUM trajectory files and the GroundTruth (JPL) <-> TUM (Hamilton) conversion."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from evio_lib.geometry.rotation import quat_to_rot
from evio_lib.io.errors import DataFileError
from evio_lib.io.tum import groundtruth_from_tum, groundtruth_to_tum, read_tum, write_tum
from evio_lib.sequence import GroundTruth


def _poses(rng, n=50, ns_grid=True):
    t = 1403715273.0 + np.cumsum(rng.uniform(0.001, 0.01, n)) if not ns_grid else np.round(np.cumsum(rng.uniform(0.001, 0.01, n)), 9)
    p = rng.normal(size=(n, 3)) * 10.0
    q = Rotation.random(n, random_state=np.random.RandomState(7)).as_quat()
    return t, p, q


@pytest.mark.parametrize("ns_grid", [True, False])
def test_write_read_round_trip_is_exact(tmp_path, rng, ns_grid):
    t, p, q = _poses(rng, ns_grid=ns_grid)
    path = tmp_path / "traj.txt"
    write_tum(path, t, p, q)
    t2, p2, q2 = read_tum(path)
    np.testing.assert_array_equal(t2, t)
    np.testing.assert_array_equal(p2, p)
    np.testing.assert_array_equal(q2, q)
    first = path.read_text().splitlines()
    assert first[0].startswith("#") and len(first) == 51
    if ns_grid:
        assert len(first[1].split()[0].split(".")[1]) == 9  # ECD/TUM style: nanosecond decimals


def test_read_tum_comments_blank_lines_and_values(tmp_path):
    path = tmp_path / "gt.txt"
    path.write_text("# timestamp tx ty tz qx qy qz qw\n\n1.0 1 2 3 0 0 0 1\n# middle comment\n2.5 4 5 6 0 0 1 0  # yaw 180\n")
    t, p, q = read_tum(path)
    np.testing.assert_array_equal(t, [1.0, 2.5])
    np.testing.assert_array_equal(p, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(q, [[0, 0, 0, 1], [0, 0, 1, 0]])


@pytest.mark.parametrize(
    "body, message",
    [
        ("0.0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 1\n", r"traj.txt line 2: expected 8 columns \(t px py pz qx qy qz qw\), got 7"),
        ("0.0 0 0 0 0 0 0 1\n0.1 0 abc 0 0 0 0 1\n", r"traj.txt line 2: column 'py' must be a number; got 'abc'"),
        ("# c\n0.0 0 0 0 0 0 0 1\n0.1 0 0 nan 0 0 0 1\n", r"traj.txt line 3: column 'pz' must be a finite number; got '?nan"),
        ("0.0 0 0 0 0 0 0 1\n0.2 0 0 0 0 0 0 1\n\n0.1 0 0 0 0 0 0 1\n", r"traj.txt line 4: timestamp 0.1 follows 0.2 .*strictly increasing"),
        ("0.0 0 0 0 0 0 0 1\n0.0 0 0 0 0 0 0 1\n", r"traj.txt line 2: timestamp 0.0 follows 0.0 .*no duplicates"),
        ("0.0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 0\n", r"traj.txt line 2: quaternion \(qx qy qz qw\) has zero norm"),
    ],
)
def test_read_tum_errors_name_file_line_problem(tmp_path, body, message):
    path = tmp_path / "traj.txt"
    path.write_text(body)
    with pytest.raises(DataFileError, match=message):
        read_tum(path)


def test_read_tum_missing_file(tmp_path):
    with pytest.raises(ValueError, match=r"nope.txt: file not found at .*nope.txt"):
        read_tum(tmp_path / "nope.txt")


def test_write_tum_bad_input(tmp_path, rng):
    t, p, q = _poses(rng, 5)
    with pytest.raises(ValueError, match=r"q_xyzw must have shape \(5, 4\); got \(5, 3\)"):
        write_tum(tmp_path / "x.txt", t, p, q[:, :3])
    with pytest.raises(ValueError, match=r"t must be strictly increasing; got t\[1\]"):
        write_tum(tmp_path / "x.txt", t[[0, 0, 1, 2, 3]], p, q)
    with pytest.raises(ValueError, match=r"p must be finite"):
        write_tum(tmp_path / "x.txt", t, p * np.nan, q)


def test_groundtruth_conversion_matches_scipy(rng):
    t, p, q_xyzw = _poses(rng, 10)
    gt = groundtruth_from_tum(t, p, q_xyzw, body="imu")
    # scipy's Hamilton quaternion of the file gives R_BtoG; the library's JPL quaternion gives R_GtoB = R_BtoG^T
    R_BtoG = Rotation.from_quat(q_xyzw).as_matrix()
    np.testing.assert_allclose(quat_to_rot(gt.q_GtoB), np.swapaxes(R_BtoG, 1, 2), atol=1e-12)
    np.testing.assert_allclose(gt.R_BtoG, R_BtoG, atol=1e-12)
    t2, p2, q2 = groundtruth_to_tum(gt)
    np.testing.assert_array_equal(q2, q_xyzw)
    np.testing.assert_array_equal(p2, p)
    with pytest.raises(ValueError, match="gt must be a GroundTruth; got tuple"):
        groundtruth_to_tum((t, p, q_xyzw))


def test_groundtruth_tum_file_round_trip(tmp_path, rng):
    t, p, _ = _poses(rng, 8)
    R_GtoB = Rotation.random(8, random_state=np.random.RandomState(3)).as_matrix()
    from evio_lib.geometry.rotation import rot_to_quat

    gt = GroundTruth(t, p, rot_to_quat(R_GtoB), body="camera")
    write_tum(tmp_path / "gt.txt", *groundtruth_to_tum(gt))
    back = groundtruth_from_tum(*read_tum(tmp_path / "gt.txt"))
    np.testing.assert_array_equal(back.q_GtoB, gt.q_GtoB)
    np.testing.assert_allclose(back.R_BtoG, np.swapaxes(R_GtoB, 1, 2), atol=1e-12)


def test_real_openvins_tum_file(real_data_dir):
    t, p, q = read_tum(real_data_dir / "euroc_V1_01_easy_micro" / "groundtruth_openvins" / "V1_01_easy.txt")
    assert t.shape == (2895,) and p.shape == (2895, 3) and q.shape == (2895, 4)
    assert t[0] == pytest.approx(1403715273.26214) and t[-1] == pytest.approx(1403715417.96214, abs=1e-4)
    np.testing.assert_allclose(p[0], [0.878895, 2.1834, 0.948427])
    np.testing.assert_allclose(q[0], [-0.824237, -0.106942, -0.551702, 0.069433])
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-5)


# ---------------------------------------------------------------------------------------------- quaternion norms (issue 17)
BAD_QUATERNION_ROWS = [
    ("norm_2", "0 0 0 2", r"traj.txt line 3: quaternion \(qx qy qz qw\) has norm 2; expected a unit quaternion "
                          r"\(norms within 0.001 of 1 are normalised, others are not rotations\)"),
    ("norm_half", "0 0.3 0 0.4", r"traj.txt line 3: quaternion \(qx qy qz qw\) has norm 0.5; expected a unit quaternion"),
    ("norm_zero", "0 0 0 0", r"traj.txt line 3: quaternion \(qx qy qz qw\) has zero norm; expected a unit quaternion"),
    ("norm_1.002", "0 0 0 1.002", r"traj.txt line 3: quaternion \(qx qy qz qw\) has norm 1.002"),
    ("norm_0.998", "0 0 0.6 0.7969", r"traj.txt line 3: quaternion \(qx qy qz qw\) has norm 0.99"),
    ("tiny", "1e-9 0 0 0", r"traj.txt line 3: quaternion \(qx qy qz qw\) has zero norm"),
]


@pytest.mark.parametrize("q_text, message", [b[1:] for b in BAD_QUATERNION_ROWS], ids=[b[0] for b in BAD_QUATERNION_ROWS])
def test_read_tum_refuses_quaternions_that_are_not_rotations(tmp_path, q_text, message):
    path = tmp_path / "traj.txt"
    path.write_text(f"# t x y z qx qy qz qw\n0.0 0 0 0 0 0 0 1\n0.1 0 0 0 {q_text}\n0.2 0 0 0 0 0 0 1\n")
    before = path.read_bytes()
    with pytest.raises(DataFileError, match=message):
        read_tum(path)
    assert path.read_bytes() == before


def test_read_tum_normalises_near_unit_quaternions_and_keeps_unit_ones_exact(tmp_path):
    q_unit = Rotation.from_euler("xyz", [0.1, -0.2, 0.3]).as_quat()
    rows = np.array([q_unit, q_unit * 1.0009, q_unit * 0.9991, q_unit * (1 + 5e-7)])
    path = tmp_path / "traj.txt"
    write_tum(path, [0.0, 0.1, 0.2, 0.3], np.zeros((4, 3)), rows)
    t, p, q = read_tum(path)
    np.testing.assert_array_equal(q[0], rows[0])  # unit rows: the numbers of the file, bit for bit
    np.testing.assert_array_equal(q[3], rows[3])  # within 1e-6 (what GroundTruth.validate accepts): unchanged
    np.testing.assert_allclose(q[1:3], [q_unit, q_unit], atol=1e-15)  # within 1e-3: q / |q|
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), Rotation.from_quat(rows).as_matrix(), atol=1e-14)
    groundtruth_from_tum(t, p, q).validate()


def test_groundtruth_from_tum_normalises_or_names_the_row():
    t, p = [0.0, 1.0, 2.0], np.zeros((3, 3))
    gt = groundtruth_from_tum(t, p, [[0, 0, 0, 1], [0, 0, 0, 1.0005], [0, 0.6, 0, 0.7995]])
    np.testing.assert_allclose(np.linalg.norm(gt.q_GtoB, axis=1), 1.0, atol=1e-15)
    gt.validate()
    for q_bad, message in (([0, 0, 0, 2.0], r"q_xyzw\[1\]: quaternion \(qx qy qz qw\) has norm 2"),
                           ([0, 0, 0, 0.5], r"q_xyzw\[1\]: quaternion \(qx qy qz qw\) has norm 0.5"),
                           ([0, 0, 0, 0.0], r"q_xyzw\[1\]: quaternion \(qx qy qz qw\) has zero norm")):
        q = np.array([[0, 0, 0, 1.0], q_bad, [0, 0, 0, 1.0]])
        before = q.copy()
        with pytest.raises(ValueError, match=message):
            groundtruth_from_tum(t, p, q)
        np.testing.assert_array_equal(q, before)


@pytest.mark.parametrize(
    "q_bad, message",
    [
        ([0, 0, 0, 0], r"q_xyzw\[2\]: quaternion \(qx qy qz qw\) has zero norm"),
        ([0, 0, 0, 2], r"q_xyzw\[2\]: quaternion \(qx qy qz qw\) has norm 2"),
        ([0, 0, 0, np.nan], r"q_xyzw must be finite; got NaN or inf"),
        ([0, 0, np.inf, 1], r"q_xyzw must be finite; got NaN or inf"),
    ],
)
def test_write_tum_refuses_what_read_tum_refuses_and_writes_nothing(tmp_path, q_bad, message):
    q = np.tile([0.0, 0.0, 0.0, 1.0], (4, 1))
    q[2] = q_bad
    path = tmp_path / "out.txt"
    with pytest.raises(ValueError, match=message):
        write_tum(path, [0.0, 0.1, 0.2, 0.3], np.zeros((4, 3)), q)
    assert not path.exists()
    path.write_text("keep me\n")
    with pytest.raises(ValueError, match=message):
        write_tum(path, [0.0, 0.1, 0.2, 0.3], np.zeros((4, 3)), q)
    assert path.read_text() == "keep me\n"  # an existing file is left as it was


def test_the_header_names_the_body_and_a_bad_body_writes_nothing(tmp_path):
    path = tmp_path / "traj.txt"
    write_tum(path, [0.0, 0.1], [[0, 0, 0]] * 2, [[0, 0, 0, 1]] * 2, body="camera")
    assert path.read_text().splitlines()[0] == ("# timestamp tx ty tz qx qy qz qw: pose of the camera frame C in the "
                                               "world frame G")
    with pytest.raises(ValueError, match="body must be one of imu, camera or None; got 'IMU'"):
        write_tum(tmp_path / "other.txt", [0.0], [[0, 0, 0]], [[0, 0, 0, 1]], body="IMU")
    assert not (tmp_path / "other.txt").exists()
