"""The compiled renderer (evio_lib.sim.render_kernels) gives the NumPy renderer's intensities bit for bit."""
import numpy as np
import pytest

from evio_lib.geometry.camera import PinholeRadtan
from evio_lib.geometry.rotation import so3_exp
from evio_lib.sim.presets import SimulationConfig, simulate_sequence
from evio_lib.sim.scene import RENDERER_ENV, Scene, TexturedPlane, renderer_backend, scene_from_preset

pytest.importorskip("numba")


def _render_both(monkeypatch: pytest.MonkeyPatch, scene: Scene, camera, R, p, supersample: int = 1
                 ) -> tuple[np.ndarray, np.ndarray]:
    monkeypatch.setenv(RENDERER_ENV, "numpy")
    reference = scene.render_intensity(camera, R, p, supersample=supersample)
    monkeypatch.setenv(RENDERER_ENV, "numba")
    compiled = scene.render_intensity(camera, R, p, supersample=supersample)
    return reference, compiled


@pytest.mark.parametrize("preset", ["boxes_like", "aerial_like"])
def test_compiled_renderer_is_bit_identical_on_random_poses(monkeypatch: pytest.MonkeyPatch, preset: str) -> None:
    scene = scene_from_preset(preset, seed=1)
    camera = PinholeRadtan.davis240c()  # distorted rays
    rng = np.random.default_rng(7)
    centre = np.array([0.0, 0.0, 1.5]) if preset == "boxes_like" else np.array([0.0, 0.0, 250.0])
    down = np.column_stack([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    compared = 0
    for k in range(40):
        R = so3_exp(rng.normal(0.0, 1.5, 3)) if preset == "boxes_like" else down @ so3_exp(rng.normal(0.0, 0.4, 3))
        p = centre + rng.normal(0.0, 1.0 if preset == "boxes_like" else 30.0, 3)
        reference, compiled = _render_both(monkeypatch, scene, camera, R, p, supersample=2 if k < 4 else 1)
        assert compiled.dtype == np.float32 and compiled.shape == (camera.height, camera.width)
        np.testing.assert_array_equal(compiled, reference)
        compared += int(np.ptp(reference) > 0)
    assert compared >= 30  # the poses see texture, not only the background


def test_compiled_renderer_handles_wrap_clip_backface_and_misses(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(3)
    tiled = TexturedPlane([-3.0, -3.0, 4.0], [6.0, 0, 0], [0, 6.0, 0], rng.random((16, 24), dtype=np.float32),
                          texture_repeat=(5.0, 3.0))
    one_sided = TexturedPlane([-0.5, -0.5, 2.0], [1.0, 0, 0], [0, 1.0, 0], rng.random((8, 8), dtype=np.float32),
                              two_sided=False)
    crossing = TexturedPlane([-1.0, 0.4, -1.0], [2.0, 0, 0], [0, 0, 4.0], rng.random((32, 32), dtype=np.float32))
    scene = Scene([tiled, one_sided, crossing], background=0.3)
    camera = PinholeRadtan(fx=60.0, fy=60.0, cx=31.5, cy=23.5, width=64, height=48)
    poses = [(np.eye(3), np.zeros(3)),  # all three planes, one crossing the camera plane (near clipping)
             (so3_exp([0.0, np.pi, 0.0]), np.array([0.0, 0.0, 6.0])),  # the one-sided plane from behind
             (so3_exp([0.0, np.pi / 2, 0.0]), np.zeros(3)),  # mostly background
             (so3_exp([0.3, -0.2, 0.1]), np.array([0.1, -0.2, 3.99]))]  # close to the tiled plane
    for R, p in poses:
        reference, compiled = _render_both(monkeypatch, scene, camera, R, p)
        np.testing.assert_array_equal(compiled, reference)


def test_renderer_backend_reads_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(RENDERER_ENV, "numpy")
    assert renderer_backend() == "numpy"
    monkeypatch.setenv(RENDERER_ENV, "NumBa")
    assert renderer_backend() == "numba"
    monkeypatch.delenv(RENDERER_ENV)
    assert renderer_backend() == "numba"  # numba imports here (importorskip above)
    monkeypatch.setenv(RENDERER_ENV, "cuda")
    with pytest.raises(ValueError, match="EVIO_RENDERER must be one of auto, numba, numpy; got 'cuda'"):
        renderer_backend()


def test_recording_is_the_same_with_either_renderer(monkeypatch: pytest.MonkeyPatch) -> None:
    config = SimulationConfig(preset="boxes_like", duration=0.25, seed=2)
    recordings = {}
    for backend in ("numpy", "numba"):
        monkeypatch.setenv(RENDERER_ENV, backend)
        recordings[backend] = simulate_sequence(config, jobs=1)
    reference, compiled = recordings["numpy"], recordings["numba"]
    assert len(reference.events) > 10_000 and len(reference.frames) >= 5
    np.testing.assert_array_equal(compiled.events, reference.events)
    np.testing.assert_array_equal(compiled.frames, reference.frames)


def test_exact_plane_corners_resolve_like_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    """Rays through a plane's exact corner give edge functions of +0 and -0: the tie must break as np.minimum's."""
    texture = np.random.default_rng(0).random((8, 8), dtype=np.float32)
    camera = PinholeRadtan(fx=20.0, fy=20.0, cx=8.0, cy=6.0, width=17, height=13)  # pixel centres on whole rays
    compared = 0
    for origin in ([0.0, 0.0, 2.0], [-1.0, 0.0, 2.0], [0.0, -1.0, 4.0], [-0.5, -0.5, 1.0]):
        for axis_u, axis_v in (([2.0, 0, 0], [0, -2.0, 0]), ([2.0, 0, 0], [0, 2.0, 0]), ([0, 2.0, 0], [2.0, 0, 0])):
            scene = Scene([TexturedPlane(origin, axis_u, axis_v, texture)], background=0.3)
            reference, compiled = _render_both(monkeypatch, scene, camera, np.eye(3), np.zeros(3))
            np.testing.assert_array_equal(compiled, reference)
            compared += 1
    assert compared == 12


def test_kernels_that_cannot_load_fall_back_to_numpy_or_are_named(monkeypatch: pytest.MonkeyPatch) -> None:
    import evio_lib.sim.scene as scene_module

    problem = "Numba cannot load the kernels (RuntimeError: cannot cache function); set NUMBA_CACHE_DIR"
    monkeypatch.setattr(scene_module, "_KERNELS_PROBLEM", [problem])
    monkeypatch.delenv(RENDERER_ENV, raising=False)
    assert renderer_backend() == "numpy"
    monkeypatch.setenv(RENDERER_ENV, "numba")
    with pytest.raises(ValueError, match="EVIO_RENDERER=numba cannot be used here: Numba cannot load .*EVIO_RENDERER=numpy"):
        renderer_backend()


def test_a_camera_with_non_finite_rays_is_refused_by_both_renderers(monkeypatch: pytest.MonkeyPatch) -> None:
    class BrokenCamera:
        width, height = 8, 6

        def __init__(self) -> None:
            ys, xs = np.mgrid[0:6, 0:8]
            self._grid = np.stack([(xs - 3.5) / 10.0, (ys - 2.5) / 10.0], axis=-1)
            self._grid[2, 3] = np.nan

        def normalized_grid(self) -> np.ndarray:
            return self._grid

    scene = Scene([TexturedPlane([-1.0, -1.0, 2.0], [2.0, 0, 0], [0, 2.0, 0], np.full((4, 4), 0.5, np.float32))])
    for backend in ("numpy", "numba"):
        monkeypatch.setenv(RENDERER_ENV, backend)
        with pytest.raises(ValueError, match="normalized_grid\\(\\) must be finite; 1 pixels have NaN/inf rays"):
            scene.render_intensity(BrokenCamera(), np.eye(3), np.zeros(3))
