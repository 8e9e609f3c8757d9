"""Tests of evio_lib.frontend.grid against a brute-force loop."""
import numpy as np
import pytest

from evio_lib.frontend.grid import FeatureGrid


def _brute_force(grid, pixels, priority, occupied):
    """Visit points by priority (ties: lower index) and keep one while its cell has room."""
    used = np.array(occupied).copy()
    kept = []
    for i in sorted(range(len(pixels)), key=lambda k: (-priority[k], k)):
        col = min(max(int(np.floor(pixels[i][0] * grid.cols / grid.width)), 0), grid.cols - 1)
        row = min(max(int(np.floor(pixels[i][1] * grid.rows / grid.height)), 0), grid.rows - 1)
        cell = row * grid.cols + col
        if used[cell] < grid.per_cell:
            used[cell] += 1
            kept.append(i)
    return kept


@pytest.mark.parametrize("seed", range(5))
def test_keep_best_equals_the_brute_force_loop(seed):
    rng = np.random.default_rng(seed)
    grid = FeatureGrid(width=240, height=180, rows=4, cols=5, per_cell=3)
    pixels = rng.uniform([-5, -5], [245, 185], size=(200, 2))
    priority = rng.integers(0, 5, size=200).astype(float)  # many ties
    occupied = rng.integers(0, 4, size=20)
    kept = grid.keep_best(pixels, priority, occupied)
    assert kept.tolist() == _brute_force(grid, pixels, priority, occupied)
    counts = grid.counts(pixels[kept]) + occupied
    assert np.all(counts[grid.counts(pixels[kept]) > 0] <= 3)


def test_cells_cover_the_image_row_major_and_clip_the_border():
    grid = FeatureGrid(width=240, height=180)
    assert grid.num_cells == 20 and grid.capacity == 60
    assert grid.cell_of([[47.9, 44.9], [48.0, 45.0], [-3.0, 500.0], [1e4, -1.0]]).tolist() == [0, 6, 15, 4]
    assert grid.counts(np.zeros((0, 2))).tolist() == [0] * 20


def test_bad_input():
    with pytest.raises(ValueError, match="rows"):
        FeatureGrid(width=240, height=180, rows=0)
    grid = FeatureGrid(width=240, height=180)
    with pytest.raises(ValueError, match="pixels"):
        grid.cell_of([[np.nan, 1.0]])
    with pytest.raises(ValueError, match="priority"):
        grid.keep_best([[1.0, 1.0]], [1.0, 2.0])
    with pytest.raises(ValueError, match="occupied"):
        grid.keep_best([[1.0, 1.0]], [1.0], occupied=[0, 1])
