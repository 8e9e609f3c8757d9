"""The feature grid: the image split into rows x cols cells, each holding at most a fixed number of features.

Thesis §3.3.5: at most N features per image, spread evenly: with a 4 x 5 grid of regions, at most the strongest N/20
features of each region are kept, so that when weak features are discarded the rest still cover the whole image.
The tracker uses the same grid twice: to cap the features it keeps tracking (older tracks first, as msckf_vio's
``pruneGridFeatures`` does) and to add new detections only to cells that have room.

Cells are in pixel coordinates of the raw image: cell (r, c) covers columns [c W / cols, (c + 1) W / cols) and rows
[r H / rows, (r + 1) H / rows); points on or beyond the border are clipped into the outer cells.
"""
from __future__ import annotations

from dataclasses import dataclass
from numbers import Integral

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FeatureGrid"]


def _positive_int(value: object, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1; got {value!r}")
    return int(value)


@dataclass(frozen=True)
class FeatureGrid:
    """A rows x cols grid over a width x height image with ``per_cell`` features at most in each cell.

    Args:
        width, height: image size, pixels.
        rows, cols: grid size (thesis: 4 x 5).
        per_cell: cap of each cell (thesis: N / 20 with N the features per image).

    >>> grid = FeatureGrid(width=240, height=180, rows=4, cols=5, per_cell=3)
    >>> grid.cell_of([[0.0, 0.0], [239.0, 179.0], [50.0, 50.0]]).tolist()
    [0, 19, 6]
    """

    width: int
    height: int
    rows: int = 4
    cols: int = 5
    per_cell: int = 3

    def __post_init__(self) -> None:
        for name in ("width", "height", "rows", "cols", "per_cell"):
            object.__setattr__(self, name, _positive_int(getattr(self, name), name))

    @property
    def num_cells(self) -> int:
        """Return rows * cols."""
        return self.rows * self.cols

    @property
    def capacity(self) -> int:
        """Return the most features the grid holds, rows * cols * per_cell."""
        return self.num_cells * self.per_cell

    def cell_of(self, pixels: ArrayLike) -> NDArray[np.int64]:
        """Return the (K,) row-major cell index r * cols + c of pixels (K, 2) given as (x, y)."""
        uv = np.asarray(pixels, dtype=np.float64)
        if uv.size == 0:
            uv = uv.reshape(0, 2)
        if uv.ndim != 2 or uv.shape[1] != 2 or not np.isfinite(uv).all():
            raise ValueError(f"pixels must be a finite (K, 2) array of (x, y); got shape {uv.shape}")
        c = np.clip(np.floor(uv[:, 0] * self.cols / self.width), 0, self.cols - 1).astype(np.int64)
        r = np.clip(np.floor(uv[:, 1] * self.rows / self.height), 0, self.rows - 1).astype(np.int64)
        return r * self.cols + c

    def counts(self, pixels: ArrayLike) -> NDArray[np.int64]:
        """Return the (rows * cols,) number of pixels (K, 2) in each cell."""
        return np.bincount(self.cell_of(pixels), minlength=self.num_cells).astype(np.int64)

    def keep_best(self, pixels: ArrayLike, priority: ArrayLike,
                  occupied: ArrayLike | None = None) -> NDArray[np.intp]:
        """Return the indices of the points to keep: per cell, the highest ``priority`` first, up to the room left.

        Args:
            pixels: (K, 2) candidate pixels (x, y).
            priority: (K,) ranking, higher first (e.g. detector score, or track age); ties keep the lower index.
            occupied: (rows * cols,) features already in each cell (their room is used up first), default none.

        Returns the kept indices in descending priority order.

        >>> grid = FeatureGrid(width=100, height=100, rows=1, cols=2, per_cell=2)
        >>> pts = [[10, 10], [20, 10], [30, 10], [70, 10]]
        >>> grid.keep_best(pts, [0.1, 0.9, 0.5, 0.2]).tolist()
        [1, 2, 3]
        >>> grid.keep_best(pts, [0.1, 0.9, 0.5, 0.2], occupied=[1, 2]).tolist()
        [1]
        """
        cells = self.cell_of(pixels)
        score = np.asarray(priority, dtype=np.float64)
        if score.shape != cells.shape or not np.isfinite(score).all():
            raise ValueError(f"priority must be a finite (K,) array with K = {cells.shape[0]}; got shape {score.shape}")
        used = np.zeros(self.num_cells, np.int64)
        if occupied is not None:
            used = np.asarray(occupied, dtype=np.int64).copy()
            if used.shape != (self.num_cells,):
                raise ValueError(f"occupied must have shape ({self.num_cells},); got {used.shape}")
        order = np.lexsort((np.arange(cells.shape[0]), -score))  # priority descending, then index
        # rank of each point among the points of its cell, in priority order
        sorted_cells = cells[order]
        by_cell = np.argsort(sorted_cells, kind="stable")
        first = np.searchsorted(sorted_cells[by_cell], np.arange(self.num_cells))
        rank = np.empty(order.shape[0], np.int64)
        rank[by_cell] = np.arange(order.shape[0]) - first[sorted_cells[by_cell]]
        keep = rank < (self.per_cell - used[sorted_cells])
        return order[keep].astype(np.intp)
