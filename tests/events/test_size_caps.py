"""Sizes that would exhaust memory and window counts that would never end are refused up front, with the numbers.

Caps: MAX_SENSOR_PIXELS and MAX_WINDOWS (events.representations), MAX_FRAME_MEMORY_GIB (reconstruct),
MAX_EVENT_FRAME_RATE_HZ (pipeline event frames), MAX_RECORDING_DURATION_S (sim.presets) and MAX_TRAJECTORY_DURATION_S
(sim.trajectory); each through the library and the command line.
"""
from __future__ import annotations

import numpy as np
import pytest

from evio_lib.events import representations as rep
from evio_lib.events.array import EVENT_DTYPE, make_events


def _events(n: int = 2000, span: float = 1.0) -> np.ndarray:
    rng = np.random.default_rng(0)
    return make_events(np.sort(rng.uniform(0, span, n)), rng.integers(0, 32, n), rng.integers(0, 24, n),
                       rng.choice([-1, 1], n))


def test_library_sensor_size_cap():
    ev = _events()
    with pytest.raises(ValueError, match=r"is 1e\+10 pixels; the most is 16,777,216 \(4096 x 4096, MAX_SENSOR_PIXELS"):
        rep.polarity_frame(ev, 100000, 100000)
    with pytest.raises(ValueError, match=r"the sensor size 100000x100000 is 1e\+10 pixels"):
        from evio_lib.events.reconstruct import create_reconstructor

        create_reconstructor("direct", 100000, 100000)
    rep.polarity_frame(ev, 4096, 4096 // 2)  # within the cap


def test_library_window_count_caps():
    many = np.zeros(rep.MAX_WINDOWS + 1, dtype=EVENT_DTYPE)  # a window per event: one more than the cap
    with pytest.raises(ValueError, match=r"n_events=1 for 1000001 events gives about 1e\+06 windows; the most is "
                                         r"1,000,000 \(MAX_WINDOWS\) \(use n_events >= 2\)"):
        rep.count_windows(many, 1)
    assert len(rep.count_windows(many, 2)) == (rep.MAX_WINDOWS + 1) // 2
    with pytest.raises(ValueError, match=r"a window duration of 1e-09 s over 0.99\d* s gives about 9.99e\+08 windows; "
                                         r"the most is 1,000,000 \(MAX_WINDOWS\) \(use a duration >= 9.9\d*e-07 s\)"):
        rep.time_windows(_events(), 1e-9)


def test_library_event_frame_rate_cap():
    from evio_lib.geometry.camera import PinholeRadtan
    from evio_lib.pipeline.frames import event_frames
    from evio_lib.sequence import Sequence

    camera = PinholeRadtan(fx=30.0, fy=30.0, cx=16.0, cy=12.0, width=32, height=24)
    seq = Sequence("tiny", camera=camera, events=_events(20000, 0.5))
    with pytest.raises(ValueError, match=r"window_fraction \(--window-fraction\) 1e-09 gives about 2e\+04 windows of "
                                         r"1 event\(s\) .* over 0.5 s; the most is 500 .*use n >= 0.052"):
        next(event_frames(seq, "direct", window_fraction=1e-9))
    assert len(list(event_frames(seq, "direct", window_fraction=2.0))) == 20000 // (2 * 32 * 24)


def test_library_duration_caps():
    from evio_lib.sim.presets import MAX_RECORDING_DURATION_S, SimulationConfig
    from evio_lib.sim.trajectory import MAX_TRAJECTORY_DURATION_S, trajectory_from_preset

    with pytest.raises(ValueError, match=r"duration 1e\+09 s is longer than the longest simulation, 600 s "
                                         r"\(MAX_RECORDING_DURATION_S; .* GiB of memory\)"):
        SimulationConfig(duration=1e9)
    with pytest.raises(ValueError, match="longer than the longest simulation, 600 s"):
        SimulationConfig(duration=MAX_RECORDING_DURATION_S + 1, with_events=False)
    SimulationConfig(duration=MAX_RECORDING_DURATION_S + 1, with_events=False, with_frames=False)  # IMU only: 1 h
    with pytest.raises(ValueError, match=r"duration 1e\+09 s is longer than the longest trajectory, 3600 s"):
        trajectory_from_preset("boxes_like", 1e9)
    with pytest.raises(ValueError, match="longest trajectory"):
        trajectory_from_preset("aerial_like", MAX_TRAJECTORY_DURATION_S * 2)


@pytest.fixture()
def ecd_folder(tmp_path):
    ev = _events()
    folder = tmp_path / "rec"
    folder.mkdir()
    (folder / "events.txt").write_text("".join(f"{t:.9f} {x} {y} {1 if p > 0 else 0}\n"
                                               for t, x, y, p in zip(ev["t"], ev["x"], ev["y"], ev["p"])))
    return folder


def _cli(argv, capsys) -> str:
    from evio_lib.cli import main

    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in err, err
    return lines[0]


def test_command_line_caps(tmp_path, capsys, ecd_folder, monkeypatch):
    monkeypatch.setenv("EVIO_CACHE_DIR", str(tmp_path / "cache"))
    out = tmp_path / "frames"
    line = _cli(["reconstruct", ecd_folder, "--out", out, "--sensor-size", 100000, 100000, "--quiet"], capsys)
    assert line == ("error: --sensor-size 100000 100000 is 1e+10 pixels; the most is 16,777,216 (4096 x 4096, "
                    "MAX_SENSOR_PIXELS; event cameras have about 1 Mpx)")
    line = _cli(["reconstruct", ecd_folder, "--out", out, "--sensor-size", 32, 24, "--window-time", 1e-9, "--quiet"],
                capsys)
    assert line.startswith("error: --window-time 1e-09 gives about 9.99e+08 windows over the 0.999") and \
        "the most is 999 (1000 frames per recorded second, MAX_EVENT_FRAME_RATE_HZ, over 0.999 s)" in line, line
    monkeypatch.setattr(rep, "MAX_WINDOWS", 500)  # 2000 events at n H W = 1: a window per event
    line = _cli(["reconstruct", ecd_folder, "--out", out, "--sensor-size", 32, 24, "--window-fraction", 1e-9,
                 "--quiet"], capsys)
    assert line.startswith("error: --window-fraction 1e-09 gives about 2e+03 windows of 1 event(s) (n H W = 7.68e-07)"
                           " for 2,000 events; the most is 500 (MAX_WINDOWS 500; frames of 32x24") \
        and "use --window-fraction >= 0.0052" in line, line
    assert not out.exists()
    for argv in (["simulate", "boxes_like", "--out", tmp_path / "sim", "--duration", 1e9, "--quiet"],
                 ["reconstruct", "boxes_like", "--out", out, "--duration", 1e9, "--quiet"]):
        assert "is longer than the longest simulation, 600 s (MAX_RECORDING_DURATION_S" in _cli(argv, capsys)
    assert "longer than the longest trajectory, 3600 s" in _cli(["vio-sim", "boxes_like", "--duration", 1e9], capsys)
    assert not (tmp_path / "sim").exists() and not out.exists()
