"""Tests of evio_lib.sim.textures.read_gray8: OpenCV's pixels, without libpng's iCCP warning."""
import cv2
import numpy as np
import pytest

from evio_lib.sim.textures import _SKIMAGE_FILES, _skimage_data_dir, _without_png_chunk, load_texture, read_gray8


def _chunk_types(data: bytes) -> list[bytes]:
    """Return the chunk types of a PNG file, in order (an independent walk of the chunk list)."""
    types, offset = [], 8
    while offset < len(data):
        length = int.from_bytes(data[offset:offset + 4], "big")
        types.append(data[offset + 4:offset + 8])
        offset += 12 + length
    return types


@pytest.mark.parametrize("name", sorted(_SKIMAGE_FILES))
def test_same_pixels_as_cv2_imread(name):
    path = _skimage_data_dir() / _SKIMAGE_FILES[name]
    np.testing.assert_array_equal(read_gray8(path), cv2.imread(str(path), cv2.IMREAD_GRAYSCALE))


def test_page_png_has_an_icc_profile_and_loads_silently(capfd):
    data = (_skimage_data_dir() / "page.png").read_bytes()
    assert b"iCCP" in _chunk_types(data)  # the chunk libpng warns about is really there
    stripped = _without_png_chunk(data, b"iCCP")
    assert b"iCCP" not in _chunk_types(stripped)
    assert [t for t in _chunk_types(data) if t != b"iCCP"] == _chunk_types(stripped)  # nothing else dropped
    capfd.readouterr()
    load_texture("page", size=(32, 32))
    assert "libpng" not in capfd.readouterr().err  # the C library's stderr, captured at the file descriptor


def test_non_png_and_bad_files(tmp_path):
    assert _without_png_chunk(b"not a png", b"iCCP") == b"not a png"
    with pytest.raises(ValueError, match=r"image file .*missing.png could not be read"):
        read_gray8(tmp_path / "missing.png")
    (tmp_path / "text.png").write_text("hello")
    with pytest.raises(ValueError, match=r"image file .*text.png could not be decoded as an image"):
        read_gray8(tmp_path / "text.png")
