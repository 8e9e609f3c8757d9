"""Tests of `python -m evio_lib reconstruct` (evio_lib.events.reconstruction.command) on a small ECD folder."""
from __future__ import annotations

import numpy as np
import pytest

from evio_lib.events.array import make_events
from evio_lib.events.reconstruction.command import main_reconstruct, read_times_file


@pytest.fixture()
def ecd_folder(tmp_path):
    rng = np.random.default_rng(0)
    n = 4000
    ev = make_events(np.sort(rng.uniform(0, 1, n)), rng.integers(0, 32, n), rng.integers(0, 24, n),
                     rng.choice([-1, 1], n))
    folder = tmp_path / "rec"
    folder.mkdir()
    lines = [f"{t:.9f} {x} {y} {1 if p > 0 else 0}\n" for t, x, y, p in zip(ev["t"], ev["x"], ev["y"], ev["p"])]
    (folder / "events.txt").write_text("".join(lines))
    return folder


def read_listing(folder):
    return [line.split() for line in (folder / "images.txt").read_text().splitlines()]


def test_count_windows_write_one_png_per_window(ecd_folder, tmp_path):
    out = tmp_path / "frames"
    assert main_reconstruct([str(ecd_folder), "--out", str(out), "--method", "direct", "--window-fraction", "1.0",
                             "--sensor-size", "32", "24", "--quiet"]) == 0
    listing = read_listing(out)
    assert len(listing) == 4000 // (32 * 24)
    assert all((out / name).is_file() for _, name in listing)
    times = [float(t) for t, _ in listing]
    assert times == sorted(times)


def test_times_file_gives_exactly_one_frame_per_time(ecd_folder, tmp_path):
    times = tmp_path / "times.txt"
    times.write_text("# t name\n0.25 a.png\n0.5 b.png\n0.75\n2.0\n")
    out = tmp_path / "frames"
    main_reconstruct([str(ecd_folder), "--out", str(out), "--method", "high_pass", "--times", str(times),
                      "--sensor-size", "32", "24", "--quiet"])
    assert [float(t) for t, _ in read_listing(out)] == [0.25, 0.5, 0.75, 2.0]


def test_a_used_folder_is_refused_and_kept(ecd_folder, tmp_path):
    out = tmp_path / "frames"
    out.mkdir()
    (out / "mine.txt").write_text("keep")
    with pytest.raises(ValueError, match="not empty"):
        main_reconstruct([str(ecd_folder), "--out", str(out), "--method", "direct", "--sensor-size", "32", "24"])
    assert (out / "mine.txt").read_text() == "keep"
    main_reconstruct([str(ecd_folder), "--out", str(out), "--method", "direct", "--sensor-size", "32", "24",
                      "--window-time", "0.25", "--force", "--quiet"])
    assert not (out / "mine.txt").exists() and len(read_listing(out)) == 3  # [t0, t0 + 0.75] within the 1 s of events


@pytest.mark.parametrize("argv, message", [
    (["--method", "nope"], "--method"),
    (["--window-fraction", "-1"], "--window-fraction"),
    (["--window-time", "0"], "--window-time"),
    (["--sensor-size", "0", "24"], "--sensor-size"),
    (["--events", "missing.txt"], "--events"),
])
def test_bad_options_name_themselves(ecd_folder, tmp_path, argv, message):
    with pytest.raises((ValueError, FileNotFoundError), match=message):
        main_reconstruct([str(ecd_folder), "--out", str(tmp_path / "o"), *argv])
    assert not (tmp_path / "o").exists()


def test_bad_times_files(tmp_path):
    bad = tmp_path / "t.txt"
    bad.write_text("0.1\n0.05\n")
    with pytest.raises(ValueError, match="line 2: timestamps must increase"):
        read_times_file(bad)
    bad.write_text("zero\n")
    with pytest.raises(ValueError, match="line 1"):
        read_times_file(bad)
    bad.write_text("# nothing\n")
    with pytest.raises(ValueError, match="no timestamps"):
        read_times_file(bad)


def test_bfloat16_and_int8_frames_are_close_to_float32_ones(ecd_folder, tmp_path):
    import cv2

    listings = {}
    for precision in ("float32", "bfloat16", "int8"):
        out = tmp_path / precision
        assert main_reconstruct([str(ecd_folder), "--out", str(out), "--method", "firenet", "--window-fraction", "1.0",
                                 "--sensor-size", "32", "24", "--precision", precision, "--quiet"]) == 0
        listings[precision] = [cv2.imread(str(out / name), cv2.IMREAD_GRAYSCALE).astype(int)
                               for _, name in read_listing(out)]
    assert len(listings["float32"]) == len(listings["bfloat16"]) == 4000 // (32 * 24)
    for a, b in zip(listings["float32"], listings["bfloat16"]):
        assert np.abs(a - b).max() <= 6  # 8-bit frames; bfloat16 keeps 8 bits of mantissa (a few 1e-3 measured)
    levels = [np.abs(a - b) for a, b in zip(listings["float32"], listings["int8"])]
    assert len(levels) == len(listings["float32"]) and max(d.mean() for d in levels) < 2.5 and max(d.max() for d in levels) <= 15
    # int8: 1.0-1.3 levels on average, at most 7 (measured)


def test_a_times_file_that_is_not_utf8_text_is_named_with_its_line(tmp_path):
    bad = tmp_path / "t.txt"
    bad.write_bytes(b"0.1\n0.2 \xe9\n")
    with pytest.raises(ValueError, match=r"t.txt line 2: not UTF-8 text \(byte 0xe9 at column 5\)"):
        read_times_file(bad)
