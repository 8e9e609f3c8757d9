"""load_photo reads the bundled photographs without libpng's iCCP warning (page.png), with cv2.imread's pixels.

The warning comes from the C library and goes straight to file descriptor 2, so the read runs in a fresh
subprocess (no photo cached yet) and its stderr is checked.
"""
import subprocess
import sys

import cv2
import numpy as np
import pytest

from evio_lib.features.training.datasets import PHOTO_FILES, _skimage_data_dir, load_photo

_READ_ALL = """
from evio_lib.features.training.datasets import PHOTO_FILES, load_photo
for name, files in PHOTO_FILES.items():
    for index in range(len(files)):
        load_photo(name, index)
print("read", sum(len(files) for files in PHOTO_FILES.values()))
"""


def test_every_photo_loads_without_a_libpng_warning():
    assert "page" in PHOTO_FILES  # the photograph whose iCCP profile has an invalid rendering intent
    done = subprocess.run([sys.executable, "-c", _READ_ALL], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == f"read {sum(len(f) for f in PHOTO_FILES.values())}"
    assert "libpng" not in done.stderr, done.stderr


def test_the_warning_is_real_with_cv2_imread():
    """The check above can fail: a plain cv2.imread of page.png does print the warning."""
    code = ("import cv2, sys; from evio_lib.features.training.datasets import _skimage_data_dir; "
            "cv2.imread(str(_skimage_data_dir() / 'page.png'), cv2.IMREAD_GRAYSCALE)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    if "libpng warning: iCCP" not in done.stderr:
        pytest.skip("this OpenCV's libpng does not warn about page.png's profile")


@pytest.mark.parametrize("name", sorted(PHOTO_FILES))
def test_same_pixels_as_cv2_imread(name):
    for index, file in enumerate(PHOTO_FILES[name]):
        expected = cv2.imread(str(_skimage_data_dir() / file), cv2.IMREAD_GRAYSCALE).astype(np.float32) / 255.0
        np.testing.assert_array_equal(load_photo(name, index), expected)
