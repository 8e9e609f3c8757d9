"""Units and frames at the door (evio_lib.io.imu_checks): each refused case is a real or simulated recording with its
columns scaled, swapped or rotated, and the message must name the fix; the real recordings and the presets pass."""
import math
import os
from pathlib import Path

import numpy as np
import pytest

from evio_lib import cli
from evio_lib.geometry.camera import PinholeRadtan, intrinsics_problem
from evio_lib.io.ecd import read_calib, read_ecd, write_ecd
from evio_lib.io.errors import DataFileError
from evio_lib.io.euroc import read_euroc
from evio_lib.io.imu_checks import ImuUnitsError, check_bias_values, check_imu_units
from evio_lib.pipeline.command import _bias
from evio_lib.pipeline.dataset import load_dataset
from evio_lib.sequence import ImuSamples

EUROC = "euroc_V1_01_easy_micro"
DEG = 180.0 / math.pi


def _tree(folder: Path) -> dict[str, bytes]:
    """{relative path: bytes} of every regular file under ``folder`` (symbolic links by their target's name)."""
    out = {}
    for root, dirs, files in os.walk(folder, followlinks=False):
        for name in files + [d for d in dirs if os.path.islink(os.path.join(root, d))]:
            path = Path(root) / name
            key = str(path.relative_to(folder))
            out[key] = ("-> " + os.readlink(path)).encode() if path.is_symlink() else path.read_bytes()
    return out


REAL_DATA_DIR = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real"


@pytest.fixture(scope="module")
def euroc():
    if not REAL_DATA_DIR.is_dir():
        pytest.skip(f"real recordings not found at {REAL_DATA_DIR} (only present beside a CI checkout)")
    return read_euroc(REAL_DATA_DIR / EUROC, load_frames=False)


@pytest.fixture(scope="module")
def boxes():
    """3 s of the simulated boxes_like IMU and ground truth (no frames or events: 0.5 s)."""
    from evio_lib.sim.presets import SimulationConfig, simulate_sequence

    return simulate_sequence(SimulationConfig(preset="boxes_like", duration=3.0, trajectory_duration=60.0,
                                              with_events=False, with_frames=False))


def _refused(imu_t, gyro, accel, truth=None, **kw) -> str:
    with pytest.raises(ImuUnitsError) as info:
        check_imu_units(imu_t, gyro, accel, truth, source="rec", **kw)
    message = str(info.value)
    assert "\n" not in message and message.startswith("rec: ")
    return message


# ----------------------------------------------------------------------------- what must pass

def test_real_euroc_and_simulated_presets_pass(euroc, boxes):
    imu = euroc.imu
    summary = check_imu_units(imu.t, imu.gyro, imu.accel, euroc.groundtruth_imu)
    assert "gyro / truth angular rate 1.0" in summary and "gravity and axes checked" in summary
    assert "still gyro" in check_imu_units(imu.t, imu.gyro, imu.accel)  # without the truth: the still stretch
    summary = check_imu_units(boxes.imu.t, boxes.imu.gyro, boxes.imu.accel, boxes.groundtruth_imu,
                              gravity_G=boxes.metadata["gravity_G"])
    assert "gravity and axes checked" in summary
    # the camera ground truth with the recording's extrinsics gives the same verdict
    check_imu_units(boxes.imu.t, boxes.imu.gyro, boxes.imu.accel, boxes.groundtruth, R_CtoI=boxes.R_CtoI)


def test_preset_through_load_dataset_passes(tmp_path, monkeypatch):
    monkeypatch.setenv("EVIO_CACHE_DIR", str(tmp_path))  # never the project's cache
    import evio_lib.pipeline.dataset as dataset
    from evio_lib.sim.presets import SimulationConfig, simulate_sequence

    def imu_only(preset, duration=None, seed=0, with_events=False, cache=True, progress=False, start=0.0,
                 aps_exposure_s=None, speed=1.0):
        return simulate_sequence(SimulationConfig(preset=preset, duration=duration, trajectory_duration=60.0,
                                                  seed=seed, with_events=False, with_frames=False,
                                                  start_time=start))  # skip rendering
    monkeypatch.setattr(dataset, "simulate_preset", imu_only)
    data = load_dataset("boxes_like", duration=2.5, need_frames=False)
    assert data.notes == ("extrinsics: from the recording (simulator)",)  # the stored noise: no default named


def test_real_slider_and_rotation_calibrations_pass(real_data_dir):
    assert intrinsics_problem(read_calib(real_data_dir / "ecd_slider_depth_slice" / "calib.txt", 240, 180)) is None
    for calib in sorted((real_data_dir / "ecd_rotation_slices").glob("*/calib.txt")):
        read_calib(calib, 240, 180)


# ----------------------------------------------------------------------------- refused: units and columns

def test_accelerometer_in_g_and_milli_g(euroc, boxes):
    imu = euroc.imu
    message = _refused(imu.t, imu.gyro, imu.accel / 9.80665, euroc.groundtruth_imu)
    assert "accelerometer looks like it is in g" in message and "multiply the accelerometer by 9.80665" in message
    message = _refused(boxes.imu.t, boxes.imu.gyro, boxes.imu.accel / 9.80665)
    assert "multiply the accelerometer by 9.80665" in message
    message = _refused(imu.t, imu.gyro, imu.accel / 9.80665 * 1000.0)
    assert "milli-g" in message and "multiply the accelerometer by 0.00980665" in message
    message = _refused(imu.t, imu.gyro, imu.accel * 16384 / 9.80665)  # raw counts of a ±2 g part
    assert "divide by the LSB per g" in message


def test_a_motion_played_faster_may_accelerate_more():
    """speed: a preset played s times faster accelerates s^2 times more, so the plausible median |a| grows with it."""
    t = np.arange(400) * 0.005
    gyro = np.tile([0.3, -0.2, 0.1], (400, 1))
    accel = np.tile([0.0, 60.0, 9.81], (400, 1))  # a median of about 6 g: beyond a hand at the preset's own speed
    with pytest.raises(ImuUnitsError, match="median |a| = 60.8 is no specific force"):
        check_imu_units(t, gyro, accel)
    assert check_imu_units(t, gyro, accel, speed=2.0).startswith("IMU units: median |a| 60.8")
    with pytest.raises(ImuUnitsError, match="is no specific force"):
        check_imu_units(t, gyro, 3.0 * accel, speed=2.0)  # beyond 16 g even so


def test_gyro_and_accelerometer_columns_swapped(euroc, boxes):
    message = _refused(euroc.imu.t, euroc.imu.accel, euroc.imu.gyro, euroc.groundtruth_imu,
                       columns="timestamp, w xyz, a xyz")
    assert "columns look swapped" in message and "put the columns in the order timestamp, w xyz, a xyz" in message
    assert "swapped" in _refused(boxes.imu.t, boxes.imu.accel, boxes.imu.gyro)


def test_gyro_in_deg_per_s_with_ground_truth(euroc, boxes):
    message = _refused(euroc.imu.t, euroc.imu.gyro * DEG, euroc.imu.accel, euroc.groundtruth_imu)
    assert "gyro looks like it is in deg/s" in message and "times the ground truth's angular rate" in message
    assert "multiply the gyro by pi/180" in message
    ratio = float(message.split("reads ")[1].split(" times")[0])
    assert 50 < ratio < 65  # 57.3
    assert "pi/180" in _refused(boxes.imu.t, boxes.imu.gyro * DEG, boxes.imu.accel, boxes.groundtruth_imu)


def test_gyro_in_deg_per_s_without_ground_truth(euroc, boxes):
    # a still stretch: the gyro reads its bias, 57.3 times too large
    message = _refused(euroc.imu.t, euroc.imu.gyro * DEG, euroc.imu.accel)
    assert "where the accelerometer is still it reads" in message and "pi/180" in message
    assert "pi/180" in _refused(boxes.imu.t, boxes.imu.gyro * DEG, boxes.imu.accel)
    # no still stretch: a steady spin of 1 rad/s about gravity, in deg/s, is beyond any MEMS gyro's range
    t = np.arange(2000) * 1e-3
    gyro = np.tile([0.0, 0.0, 1.0 * DEG], (2000, 1))
    message = _refused(t, gyro, np.tile([0.0, 0.0, 9.81], (2000, 1)))
    assert "100 % of the samples read more than 34.9 rad/s" in message and "pi/180" in message


# ----------------------------------------------------------------------------- refused: gravity on the wrong axis

@pytest.mark.parametrize("value", [1e200, -1e200, 5e4])
def test_a_glitched_sample_is_left_out_not_blamed_on_the_axes(boxes, value):
    import warnings

    accel, gyro = boxes.imu.accel.copy(), boxes.imu.gyro.copy()
    accel[len(accel) // 2, 1] = value                    # one absurd accelerometer sample
    gyro[len(gyro) // 3, 0] = value                      # and one absurd gyro sample
    with warnings.catch_warnings():
        warnings.simplefilter("error")                   # no numpy overflow warning reaches the screen
        summary = check_imu_units(boxes.imu.t, gyro, accel, boxes.groundtruth_imu,
                                  gravity_G=boxes.metadata["gravity_G"])
    assert "gravity and axes checked" in summary and "2 glitched samples left out of these checks" in summary
    # a whole column of another unit is no glitch: still diagnosed
    assert "in g" in _refused(boxes.imu.t, gyro, accel / 9.81, boxes.groundtruth_imu,
                              gravity_G=boxes.metadata["gravity_G"])


def test_gravity_on_an_axis_the_truth_contradicts(euroc, boxes):
    imu, truth = euroc.imu, euroc.groundtruth_imu
    message = _refused(imu.t, imu.gyro, imu.accel[:, [2, 1, 0]], truth)  # x and z exchanged
    assert "gravity lies on an axis the ground truth contradicts" in message
    assert "the truth puts it on the IMU's +x" in message and "the accelerometer on +z" in message
    assert "reorder or flip the accelerometer columns" in message
    message = _refused(imu.t, imu.gyro, -imu.accel, truth)  # gravity instead of the specific force
    assert "deg away from up" in message and "the truth puts it on the IMU's +x" in message
    assert "the accelerometer on -x" in message
    rotated = boxes.imu.accel @ np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]).T
    message = _refused(boxes.imu.t, boxes.imu.gyro, rotated[:, [0, 2, 1]], boxes.groundtruth_imu)
    assert "contradicts" in message
    # the camera ground truth with the recording's extrinsics sees it too
    assert "contradicts" in _refused(boxes.imu.t, boxes.imu.gyro, boxes.imu.accel[:, [1, 2, 0]], boxes.groundtruth,
                                     R_CtoI=boxes.R_CtoI)


def test_mirrored_or_swapped_axes_off_gravity_are_refused(euroc, boxes):
    """A swap of the two axes gravity does not lie on (EuRoC's y and z: x is up) passes the gravity test; the
    motion refuses it and names the order that fits the truth."""
    imu, truth = euroc.imu, euroc.groundtruth_imu
    message = _refused(imu.t, imu.gyro, imu.accel[:, [0, 2, 1]], truth)
    assert "the accelerometer's axes" in message and "x = ax, y = az, z = ay" in message
    assert "gyro's axes" not in message
    message = _refused(imu.t, imu.gyro * [1.0, 1.0, -1.0], imu.accel, truth)
    assert "the gyro's axes" in message and "z = -wz" in message and "accelerometer's axes" not in message
    message = _refused(boxes.imu.t, boxes.imu.gyro[:, [1, 0, 2]], boxes.imu.accel, boxes.groundtruth_imu)
    assert "x = wy, y = wx, z = wz" in message
    message = _refused(boxes.imu.t, boxes.imu.gyro, boxes.imu.accel * [-1.0, 1.0, 1.0], boxes.groundtruth_imu)
    assert "x = -ax, y = ay, z = az" in message


def test_axes_are_checked_on_a_short_overlap_and_not_without_motion(boxes):
    """1.5 s of truth suffice (the check once needed 2 s and let a flipped axis through); a still IMU with any
    axis order explains a still truth equally well, so it passes."""
    imu, truth = boxes.imu, boxes.groundtruth_imu
    short = imu.t <= imu.t[0] + 1.5
    assert "x = -ax" in _refused(imu.t[short], imu.gyro[short], (imu.accel * [-1.0, 1.0, 1.0])[short], truth)
    summary = check_imu_units(imu.t[short], imu.gyro[short], imu.accel[short], truth)
    assert "gravity and axes checked" in summary
    tiny = imu.t <= imu.t[0] + 0.3
    assert "axes not checked (the ground truth shares 0.30 s" in check_imu_units(imu.t[tiny], imu.gyro[tiny],
                                                                                 imu.accel[tiny], truth)
    n = 2000
    t = np.arange(n) * 0.005
    from evio_lib.sequence import GroundTruth

    still = GroundTruth(t=t, p_BinG=np.zeros((n, 3)), q_GtoB=np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)), body="imu")
    accel = np.tile([0.0, 0.0, 9.81], (n, 1))
    gyro = np.tile([0.002, -0.001, 0.003], (n, 1))
    assert "gravity and axes checked" in check_imu_units(t, gyro[:, [1, 0, 2]], accel * [-1.0, 1.0, 1.0], still)


# ----------------------------------------------------------------------------- readers and the command line

def _euroc_copy(real: Path, tmp: Path, gyro_scale: float = 1.0, accel_scale: float = 1.0, noise: str | None = None,
                intrinsics: str | None = None) -> Path:
    """A EuRoC folder of links to the real slice, with imu0 (and optionally cam0/sensor.yaml) rewritten."""
    root = tmp / "V1_01_user"
    (root / "mav0" / "imu0").mkdir(parents=True)
    os.symlink(real / "groundtruth_openvins", root / "groundtruth_openvins")
    if intrinsics is None:
        os.symlink(real / "mav0" / "cam0", root / "mav0" / "cam0")
    else:
        (root / "mav0" / "cam0").mkdir()
        os.symlink(real / "mav0" / "cam0" / "data", root / "mav0" / "cam0" / "data")
        os.symlink(real / "mav0" / "cam0" / "data.csv", root / "mav0" / "cam0" / "data.csv")
        text = (real / "mav0" / "cam0" / "sensor.yaml").read_text()
        start = text.index("intrinsics:")
        end = text.index("\n", start)
        (root / "mav0" / "cam0" / "sensor.yaml").write_text(text[:start] + f"intrinsics: {intrinsics}" + text[end:])
    lines = (real / "mav0" / "imu0" / "data.csv").read_text().splitlines()
    out = [lines[0]]
    for line in lines[1:]:
        v = line.split(",")
        w = [repr(float(x) * gyro_scale) for x in v[1:4]]
        a = [repr(float(x) * accel_scale) for x in v[4:7]]
        out.append(",".join([v[0], *w, *a]))
    (root / "mav0" / "imu0" / "data.csv").write_text("\n".join(out) + "\n")
    yaml = (real / "mav0" / "imu0" / "sensor.yaml").read_text()
    if noise is not None:
        start = yaml.index("gyroscope_noise_density:")
        end = yaml.index("\n", start)
        yaml = yaml[:start] + f"gyroscope_noise_density: {noise}" + yaml[end:]
    (root / "mav0" / "imu0" / "sensor.yaml").write_text(yaml)
    return root


def _run_refused(capsys, args: list[str], folder: Path) -> str:
    before = _tree(folder.parent)
    code = cli.main(["run", *args, "--quiet"])
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 2, captured.err
    assert len(lines) == 1 and lines[0].startswith("error: "), captured.err
    assert _tree(folder.parent) == before  # the user's recording is unchanged, nothing written beside it
    return lines[0]


def test_run_refuses_a_euroc_gyro_in_deg_per_s(real_data_dir, tmp_path, capsys):
    folder = _euroc_copy(real_data_dir / EUROC, tmp_path, gyro_scale=DEG)
    line = _run_refused(capsys, [str(folder)], folder)
    assert line.startswith("error: mav0/imu0/data.csv: the gyro looks like it is in deg/s") and "pi/180" in line


def test_run_refuses_an_ecd_accelerometer_in_g(boxes, tmp_path, capsys):
    seq = boxes.slice_time(0.0, 3.1)
    seq.imu = ImuSamples(boxes.imu.t, boxes.imu.gyro, boxes.imu.accel / 9.80665)
    folder = write_ecd(seq, tmp_path / "user_rec")
    line = _run_refused(capsys, [str(folder)], folder)
    assert line.startswith("error: imu.txt: the accelerometer looks like it is in g") and "9.80665" in line
    with pytest.raises(ImuUnitsError, match="imu.txt: the accelerometer looks like it is in g"):
        read_ecd(folder)


def test_run_refuses_implausible_bias_init(tmp_path, capsys):
    folder = tmp_path / "rec"
    folder.mkdir()
    line = _run_refused(capsys, [str(folder), "--bias-init", "1e6,0,0,0,0,0"], folder)
    assert "--bias-init: gyro bias bgx = 1e+06 rad/s is implausible: |b_g| must be <= 0.5 rad/s" in line
    with pytest.raises(ValueError, match=r"accelerometer bias baz = 9.81 m/s\^2 is implausible: \|b_a\| must be <= 3"):
        _bias("0,0,0,0,0,9.81")
    with pytest.raises(ValueError, match=r"gyro bias bgy = -0.6"):
        check_bias_values([0.0, -0.6, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="six finite numbers"):
        _bias("nan,0,0,0,0,0")
    assert _bias("0.01,-0.02,0.03,0.1,-0.2,0.3") == (0.01, -0.02, 0.03, 0.1, -0.2, 0.3)


# ----------------------------------------------------------------------------- noise densities and intrinsics

@pytest.mark.parametrize("value, shown", [("-1.6968e-04", "-0.00016968"), (".nan", "'.nan'"), ("nan", "nan")])
def test_euroc_negative_or_nan_noise_is_refused(real_data_dir, tmp_path, value, shown):
    folder = _euroc_copy(real_data_dir / EUROC, tmp_path, noise=value)
    with pytest.raises(DataFileError, match=r"mav0/imu0/sensor.yaml: gyroscope_noise_density must be a finite number "
                                            r">= 0; got " + shown.replace(".", r"\.")):
        read_euroc(folder, load_frames=False)


def test_stored_noise_is_refused_or_named_never_replaced(boxes, tmp_path):
    import evio_lib.pipeline.dataset as dataset

    seq = boxes.slice_time(0.0, 3.1)
    seq.metadata = dict(boxes.metadata, imu_noise={"gyro_noise_density": -1e-4, "accel_noise_density": 2e-3})
    folder = write_ecd(seq, tmp_path / "neg")
    with pytest.raises(ValueError, match=r"IMU noise: gyro_noise_density must be a finite number >= 0; got -0.0001"):
        dataset._noise_from_metadata(read_ecd(folder).metadata, str(folder))
    noise, missing = dataset._noise_from_metadata({"imu_noise": {"gyroscope_noise_density": 2e-4}}, "x")
    assert noise.gyro_noise_density == 2e-4 and missing == ["accel_noise_density", "gyro_random_walk",
                                                            "accel_random_walk"]


@pytest.mark.parametrize("calib, message", [
    ("199.1 198.8 367.2 248.4 -0.36 0.15 0 0 0", r"principal point \(cx, cy\) = \(367.2, 248.4\) lies outside the 240 x "
                                                 r"180 image"),
    ("199.1 198.8 -20 110.7 -0.36 0.15 0 0 0", r"principal point .* outside"),
    ("0.199 0.198 132.2 110.7 -0.36 0.15 0 0 0", r"fx = 0.199 px gives a field of view of 180 degrees"),
    ("19910 19880 132.2 110.7 0 0 0 0 0", r"fx = 19910 px gives a field of view of 0.691 degrees"),
    ("199.1 598.8 132.2 110.7 0 0 0 0 0", r"fy / fx = 3.01"),
    ("-199.1 198.8 132.2 110.7 0 0 0 0 0", r"fx must be a positive focal length"),
    ("199.1 198.8 132.2 110.7 1e6 0.15 0 0 0", r"the distortion \(k1 1e\+06.*\) scales the image border by 9\d"),
    ("199.1 198.8 132.2 110.7 -1.0 0.15 0 0 0", r"the distortion .* cannot be inverted at the image border.*folds"),
])
def test_ecd_calibration_outside_the_image_is_refused(tmp_path, calib, message):
    folder = tmp_path / "rec"
    folder.mkdir()
    (folder / "events.txt").write_text("0.1 1 2 1\n")
    (folder / "calib.txt").write_text(calib + "\n")
    before = _tree(folder)
    with pytest.raises(DataFileError, match=r"calib.txt.*: " + message):
        read_ecd(folder)
    with pytest.raises(DataFileError, match=message):
        read_calib(folder / "calib.txt", 240, 180)
    assert _tree(folder) == before


def test_euroc_intrinsics_outside_the_resolution_are_refused(real_data_dir, tmp_path):
    folder = _euroc_copy(real_data_dir / EUROC, tmp_path, intrinsics="[458.654, 457.296, 867.215, 248.375]")
    with pytest.raises(DataFileError, match=r"mav0/cam0/sensor.yaml: intrinsics \[fu, fv, cu, cv\] against resolution "
                                            r"\[width, height\]: principal point \(cx, cy\) = \(867.215, 248.375\) lies "
                                            r"outside the 752 x 480 image"):
        read_euroc(folder, load_frames=False)


def test_calib_file_format(tmp_path):
    path = tmp_path / "davis.txt"
    path.write_text("# DAVIS346\n250 251 172.5 129.5 -0.1 0.01 0 0\n")
    cam = read_calib(path, 346, 260)
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.k1, cam.k3, cam.width) == (250.0, 251.0, 172.5, 129.5, -0.1, 0.0, 346)
    path.write_text("250 251 172.5 129.5 -0.1 0.01 0\n")
    with pytest.raises(DataFileError, match=r"davis.txt line 1: expected 8 or 9 numbers \(fx fy cx cy k1 k2 p1 p2 "
                                            r"\[k3\]\), got 7"):
        read_calib(path, 346, 260)
    path.write_text("250 251 172.5 129.5 0 0 0 0\n250 251 172.5 129.5 0 0 0 0\n")
    with pytest.raises(DataFileError, match="expected one line"):
        read_calib(path, 346, 260)
    with pytest.raises(DataFileError, match="file not found"):
        read_calib(tmp_path / "none.txt", 346, 260)
    assert intrinsics_problem(PinholeRadtan(fx=250, fy=250, cx=172.5, cy=129.5, width=346, height=260)) is None


@pytest.mark.parametrize("rows, shift, expected", [
    (0, 0.0, "groundtruth.txt holds 0 poses; a ground truth needs at least 2"),
    (1, 0.0, "groundtruth.txt holds 1 pose; a ground truth needs at least 2"),
    (None, 1e9, "groundtruth.txt covers [1e+09, 1e+09] s and the IMU [0, 3] s: they share no time"),
])
def test_run_refuses_a_groundtruth_it_cannot_use(boxes, tmp_path, capsys, rows, shift, expected):
    """An empty, one-pose or other-clock camera ground truth is named with what it holds, never a traceback."""
    seq = boxes.slice_time(0.0, 3.1)
    seq.groundtruth_imu = None
    folder = write_ecd(seq, tmp_path / "user_rec")
    lines = (folder / "groundtruth.txt").read_text().splitlines()
    if rows is not None:
        lines = lines[:rows]
    else:
        lines = [" ".join([repr(float(line.split()[0]) + shift)] + line.split()[1:]) for line in lines]
    (folder / "groundtruth.txt").write_text("".join(line + "\n" for line in lines))
    line = _run_refused(capsys, [str(folder)], folder)
    assert line.startswith(f"error: {folder}: {expected}"), line


@pytest.mark.parametrize("scale, unit", [(1e9, "nanoseconds"), (1e6, "microseconds"), (1e3, "milliseconds")])
def test_run_refuses_a_groundtruth_in_other_units_that_overlaps_the_imu(boxes, tmp_path, capsys, scale, unit):
    """Starting at 0 like the IMU, a truth in ns (or us, ms) shares time with it and was scored as a still camera
    ('path 0.000 m'); its poses lie farther apart than the whole IMU recording, which names the unit."""
    seq = boxes.slice_time(0.0, 3.1)
    seq.groundtruth_imu = None
    folder = write_ecd(seq, tmp_path / "user_rec")
    lines = (folder / "groundtruth.txt").read_text().splitlines()
    lines = [" ".join([repr(float(line.split()[0]) * scale)] + line.split()[1:]) for line in lines
             if line.strip() and not line.startswith("#")]
    (folder / "groundtruth.txt").write_text("".join(line + "\n" for line in lines))
    line = _run_refused(capsys, [str(folder)], folder)
    assert line.startswith(f"error: {folder}: groundtruth.txt covers [0, ") and f"look like {unit}" in line, line


@pytest.mark.parametrize("column, fix", [(4, "x = -wx"), (1, "x = -ax")])
def test_run_checks_axes_under_the_extrinsics_it_assumes(boxes, tmp_path, capsys, column, fix):
    """An ECD folder with a camera ground truth and no extrinsics runs with camera = IMU frame; the axes check makes
    the same assumption, so a flipped column is refused (it ran to exit 0 with 18-26 deg of orientation error)."""
    seq = boxes.slice_time(0.0, 3.1)
    seq.groundtruth_imu = None
    folder = write_ecd(seq, tmp_path / "user_rec")
    (folder / "evio_sim.json").unlink()  # no extrinsics: a user's own recording
    lines = (folder / "imu.txt").read_text().splitlines()
    flipped = []
    for line in lines:
        values = line.split()
        if values and not line.startswith("#"):
            values[column] = repr(-float(values[column]))
        flipped.append(" ".join(values))
    (folder / "imu.txt").write_text("\n".join(flipped) + "\n")
    line = _run_refused(capsys, [str(folder), "--imu-only"], folder)
    assert "the ground truth contradicts" in line and fix in line
    assert "took the camera frame as the IMU frame; if they differ, give the camera-IMU transformation with " \
           "--extrinsics FILE" in line


@pytest.mark.parametrize("factor, unit", [(1e3, "milliseconds: divide them by 1000"),
                                          (1e6, "microseconds: divide them by 1e+06"), (1e9, "nanoseconds")])
def test_imu_times_in_another_unit_are_named(euroc, factor, unit):
    """IMU times in ms, us or ns (a ground truth in seconds beside them) are named as such, not as a gap."""
    imu = euroc.imu
    message = _refused((imu.t - imu.t[0]) * factor, imu.gyro, imu.accel)
    assert "the IMU times are not seconds: the samples lie" in message and f"they look like {unit}" in message


def test_a_ground_truth_in_millimetres_or_wxyz_is_blamed_on_the_ground_truth(boxes):
    import dataclasses

    truth, imu, g = boxes.groundtruth_imu, boxes.imu, boxes.metadata["gravity_G"]
    mm = dataclasses.replace(truth, p_BinG=truth.p_BinG * 1000.0)
    with pytest.raises(ImuUnitsError, match=r"^gt.txt: the positions move at .* m/s .*millimetres or centimetres\? "
                                            r"divide them by 1000 or 100"):
        check_imu_units(imu.t, imu.gyro, imu.accel, mm, gravity_G=g, source="imu.txt", truth_source="gt.txt")
    q = truth.q_GtoB                                   # written w x y z, read as x y z w
    wxyz = dataclasses.replace(truth, q_GtoB=q[:, [3, 0, 1, 2]])
    with pytest.raises(ImuUnitsError, match=r"^gt.txt: the orientations .* read as w x y z: write them as qx qy qz "
                                            r"qw"):
        check_imu_units(imu.t, imu.gyro, imu.accel, wxyz, gravity_G=g, source="imu.txt", truth_source="gt.txt")
    # a motion played faster may move faster: the bound (100 m/s) grows with the speed
    from evio_lib.io.imu_checks import truth_speed_problem

    fast = dataclasses.replace(truth, p_BinG=truth.p_BinG * 500.0)     # 500x the preset's speed: ~170 m/s
    assert truth_speed_problem(fast) is not None
    assert truth_speed_problem(fast, max_speed=100.0 * 4) is None   # check_imu_units' bound at speed 4


def test_the_unit_check_of_a_groundtruth_over_long_and_short_imu_recordings():
    """_check_truth_times on the time axes alone: a 200 Hz truth in ms beside 140 s of IMU (28 poses inside it) is
    refused naming milliseconds, in us and ns likewise; in seconds, a 1 Hz truth over a 0.5 s IMU clip, and a truth
    that starts long before the IMU pass."""
    from types import SimpleNamespace

    from evio_lib.pipeline.dataset import _check_truth_times

    imu = np.arange(0.0, 140.0, 0.005)
    for scale, unit in ((1e3, "milliseconds"), (1e6, "microseconds"), (1e9, "nanoseconds")):
        truth = SimpleNamespace(t=np.arange(0.0, 145.0, 0.005) * scale)
        with pytest.raises(ValueError, match=rf"groundtruth.txt covers \[0, .*its times look like {unit}"):
            _check_truth_times(truth, imu, "groundtruth.txt")
    _check_truth_times(SimpleNamespace(t=np.arange(0.0, 145.0, 0.005)), imu, "groundtruth.txt")
    _check_truth_times(SimpleNamespace(t=np.arange(0.0, 60.0, 1.0)), np.arange(10.0, 10.5, 0.005), "gt")
    _check_truth_times(SimpleNamespace(t=np.arange(-3600.0, 200.0, 0.01)), imu, "gt")
