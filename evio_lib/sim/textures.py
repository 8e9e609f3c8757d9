"""Textures for the simulated scenes: float32 linear-intensity images in [0, 1], all made offline.

Three sources, none of which touches the network:

* photographs bundled inside the scikit-image wheel (read straight from its ``data`` folder with OpenCV,
  never through ``skimage.data``'s download helpers; :func:`read_gray8` drops the PNG colour profiles that make
  libpng warn), converted to gray and to linear intensity;
* procedural patterns (checkerboards, dead-leaves rectangles and blobs, value / fractal noise, stripes, tiles);
* a procedural aerial terrain (fields, roads, buildings with shadows, trees) at a chosen metres-per-pixel.

Event cameras respond to changes of log intensity, so what matters for them is contrast: the scene presets
rescale textures into an albedo-like range such as [0.05, 0.95] (:func:`rescale_contrast`), which keeps
``log(I)`` finite and gives edges log-intensity steps of tens of per cent.
Every random texture takes a seed (int or ``numpy.random.Generator``) and is reproducible.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

__all__ = [
    "available_textures",
    "read_gray8",
    "srgb_to_linear",
    "load_texture",
    "procedural_texture",
    "PROCEDURAL_KINDS",
    "rescale_contrast",
    "aerial_terrain_texture",
]

# name -> file inside scikit-image's bundled data folder (checked offline: these ship with the wheel).
_SKIMAGE_FILES = {
    "astronaut": "astronaut.png",
    "brick": "brick.png",
    "camera": "camera.png",
    "cell": "cell.png",
    "chelsea": "chelsea.png",
    "coffee": "coffee.png",
    "coins": "coins.png",
    "grass": "grass.png",
    "gravel": "gravel.png",
    "ihc": "ihc.png",
    "moon": "moon.png",
    "motorcycle": "motorcycle_left.png",
    "page": "page.png",
    "rocket": "rocket.jpg",
    "text": "text.png",
}

PROCEDURAL_KINDS = ("checkerboard", "rectangles", "blobs", "value_noise", "fractal_noise", "stripes", "tiles")


def _skimage_data_dir() -> Path:
    """Return the folder of images bundled with scikit-image (no download involved)."""
    import skimage  # imported lazily: only the package location is needed

    return Path(skimage.__file__).resolve().parent / "data"


def _without_png_chunk(data: bytes, chunk_type: bytes) -> bytes:
    """Return the PNG file ``data`` with every chunk of ``chunk_type`` removed (other bytes unchanged).

    A PNG is an 8-byte signature followed by chunks ``length (4 bytes, big endian) | type (4) | data | CRC (4)``
    (PNG specification, section 5.3); an ancillary chunk such as ``iCCP`` can be dropped without touching the rest.
    """
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        return data
    parts, offset = [data[:8]], 8
    while offset + 8 <= len(data):
        length = int.from_bytes(data[offset:offset + 4], "big")
        end = offset + 12 + length  # length + type + data + CRC
        if data[offset + 4:offset + 8] != chunk_type:
            parts.append(data[offset:end])
        offset = end
    parts.append(data[offset:])
    return b"".join(parts)


def read_gray8(path: str | Path) -> np.ndarray:
    """Return the image file at ``path`` as an (H, W) uint8 gray array (OpenCV's decoder and BT.601 gray weights).

    PNG files are decoded without their ``iCCP`` colour-profile chunk: the profiles of some bundled scikit-image
    photographs (``page.png``) carry an invalid rendering intent, on which libpng prints
    ``libpng warning: iCCP: ... invalid rendering intent`` to the terminal. OpenCV ignores colour profiles, so the
    pixels are exactly those of ``cv2.imread(path, cv2.IMREAD_GRAYSCALE)``.

    Raises:
        ValueError: the file is missing or cannot be decoded as an image.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as error:
        raise ValueError(f"image file {path} could not be read ({error.strerror or error})") from None
    gray8 = cv2.imdecode(np.frombuffer(_without_png_chunk(data, b"iCCP"), dtype=np.uint8), cv2.IMREAD_GRAYSCALE)
    if gray8 is None:
        raise ValueError(f"image file {path} could not be decoded as an image")
    return gray8


def available_textures() -> list[str]:
    """Return the sorted names accepted by :func:`load_texture` whose files are present on this machine.

    >>> "camera" in available_textures()
    True
    """
    folder = _skimage_data_dir()
    return sorted(name for name, file in _SKIMAGE_FILES.items() if (folder / file).is_file())


def _as_rng(seed: int | np.random.Generator) -> np.random.Generator:
    """Return a Generator: ``seed`` itself if it is one, else ``default_rng(seed)``."""
    if isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative int or a numpy.random.Generator; got {seed!r}")
    return np.random.default_rng(int(seed))


def _check_shape(shape: tuple[int, int], name: str = "shape") -> tuple[int, int]:
    """Return ``shape`` as (H, W) ints >= 2, else raise ValueError."""
    try:
        height, width = (int(v) for v in shape)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a (height, width) pair of ints >= 2; got {shape!r}") from None
    if height < 2 or width < 2 or (height, width) != tuple(shape):
        raise ValueError(f"{name} must be a (height, width) pair of ints >= 2; got {shape!r}")
    return height, width


def srgb_to_linear(image_srgb: np.ndarray) -> np.ndarray:
    """Return linear intensity (float32, same shape) of sRGB-encoded values in [0, 1] (IEC 61966-2-1 curve).

    ``I = c / 12.92`` for ``c <= 0.04045``, else ``I = ((c + 0.055) / 1.055) ** 2.4``.

    Args:
        image_srgb: array of encoded values in [0, 1] (any shape).

    >>> srgb_to_linear(np.array([0.0, 0.5, 1.0])).astype(float).round(3).tolist()
    [0.0, 0.214, 1.0]
    """
    c = np.asarray(image_srgb, dtype=np.float32)
    if c.size and (not np.isfinite(c).all() or c.min() < 0.0 or c.max() > 1.0):
        raise ValueError("image_srgb must hold finite values in [0, 1]")
    low = c / np.float32(12.92)  # c / 12.92
    high = ((c + np.float32(0.055)) / np.float32(1.055)) ** np.float32(2.4)  # ((c + 0.055) / 1.055)^2.4
    return np.where(c <= 0.04045, low, high).astype(np.float32)


def rescale_contrast(texture: np.ndarray, low: float = 0.05, high: float = 0.95) -> np.ndarray:
    """Return ``low + (high - low) * texture`` as float32: maps [0, 1] onto an albedo-like range [low, high].

    Keeping intensities away from 0 keeps ``log(I)`` finite for event simulation.

    Args:
        texture: (H, W) float image in [0, 1].
        low, high: output range, ``0 <= low < high <= 1``.

    >>> rescale_contrast(np.array([[0.0, 1.0]], dtype=np.float32), 0.1, 0.9).astype(float).round(3).tolist()
    [[0.1, 0.9]]
    """
    if not (0.0 <= low < high <= 1.0):
        raise ValueError(f"low and high must satisfy 0 <= low < high <= 1; got low={low!r}, high={high!r}")
    tex = np.asarray(texture, dtype=np.float32)
    return (np.float32(low) + np.float32(high - low) * tex).astype(np.float32)


def load_texture(name: str, size: tuple[int, int] | None = None) -> np.ndarray:
    """Return a bundled scikit-image photograph as a float32 (H, W) linear-intensity texture in [0, 1].

    The file is read directly from scikit-image's installed ``data`` folder (no network), converted to gray
    (ITU-R BT.601 weights, as OpenCV does), decoded from sRGB to linear intensity, and optionally resized
    with area averaging.

    Args:
        name: one of :func:`available_textures` (e.g. ``"camera"``, ``"brick"``, ``"gravel"``).
        size: optional output (height, width) in texels.

    >>> tex = load_texture("camera", size=(64, 64))
    >>> tex.shape, tex.dtype, bool(0.0 <= tex.min() and tex.max() <= 1.0)
    ((64, 64), dtype('float32'), True)
    """
    if name not in _SKIMAGE_FILES:
        raise ValueError(f"name must be one of {sorted(_SKIMAGE_FILES)}; got {name!r}")
    path = _skimage_data_dir() / _SKIMAGE_FILES[name]
    if not path.is_file():
        raise ValueError(f"texture {name!r} is not bundled with this scikit-image install (looked for {path})")
    gray8 = read_gray8(path)  # without the iCCP chunk that makes libpng warn on page.png
    texture = srgb_to_linear(gray8.astype(np.float32) / np.float32(255.0))
    if size is not None:
        height, width = _check_shape(size, "size")
        interpolation = cv2.INTER_AREA if height * width < texture.size else cv2.INTER_CUBIC
        texture = np.clip(cv2.resize(texture, (width, height), interpolation=interpolation), 0.0, 1.0)
    return np.ascontiguousarray(texture, dtype=np.float32)


# ---------------------------------------------------------------------------------------------- procedural
def _value_noise(rng: np.random.Generator, shape: tuple[int, int], cell_px: float) -> np.ndarray:
    """Return smooth noise (float32, roughly zero-mean, unit range): random values on a grid, bicubically upsampled."""
    height, width = shape
    cell = max(float(cell_px), 1.0)
    grid_h, grid_w = int(np.ceil(height / cell)) + 3, int(np.ceil(width / cell)) + 3
    coarse = rng.random((grid_h, grid_w), dtype=np.float32) - np.float32(0.5)
    fine = cv2.resize(coarse, (int(round(grid_w * cell)), int(round(grid_h * cell))), interpolation=cv2.INTER_CUBIC)
    off_y = int(rng.integers(0, max(1, fine.shape[0] - height)))
    off_x = int(rng.integers(0, max(1, fine.shape[1] - width)))
    return fine[off_y : off_y + height, off_x : off_x + width]


def _fractal_noise(rng: np.random.Generator, shape: tuple[int, int], largest_px: float, smallest_px: float = 2.0,
                   persistence: float = 0.6) -> np.ndarray:
    """Return fractal (fBm) noise: sum of value-noise octaves, amplitude * persistence per halving of the scale."""
    total = np.zeros(shape, dtype=np.float32)
    cell, amplitude = float(largest_px), 1.0
    while cell >= smallest_px:
        total += np.float32(amplitude) * _value_noise(rng, shape, cell)  # sum_o a^o noise(x / (L / 2^o))
        cell, amplitude = cell / 2.0, amplitude * persistence
    return total


def _normalise(image: np.ndarray) -> np.ndarray:
    """Return ``image`` affinely mapped onto [0, 1] (float32)."""
    low, high = float(image.min()), float(image.max())
    return ((image - low) / max(high - low, 1e-12)).astype(np.float32)


def procedural_texture(kind: str, shape: tuple[int, int], seed: int | np.random.Generator = 0,
                       scale_px: float | None = None) -> np.ndarray:
    """Return a seeded procedural float32 (H, W) texture in [0, 1] with strong, varied edges.

    Kinds:
        ``checkerboard`` squares alternating dark/bright, each with a random brightness jitter;
        ``rectangles`` dead-leaves of random axis-aligned rectangles (many corners);
        ``blobs`` dead-leaves of random ellipses;
        ``value_noise`` smooth noise at one scale; ``fractal_noise`` sum of octaves (fBm);
        ``stripes`` soft square-wave stripes at a random orientation, with noise;
        ``tiles`` panels with grout lines and per-panel brightness (floors, ceilings).

    Args:
        kind: one of :data:`PROCEDURAL_KINDS`.
        shape: (height, width) in texels.
        seed: int seed or ``numpy.random.Generator``.
        scale_px: characteristic feature size in texels (default ``min(shape) / 8``).

    >>> tex = procedural_texture("checkerboard", (32, 32), seed=1, scale_px=8)
    >>> tex.shape, tex.dtype, bool(tex.max() - tex.min() > 0.5)
    ((32, 32), dtype('float32'), True)
    """
    if kind not in PROCEDURAL_KINDS:
        raise ValueError(f"kind must be one of {PROCEDURAL_KINDS}; got {kind!r}")
    height, width = _check_shape(shape)
    rng = _as_rng(seed)
    scale = float(min(height, width)) / 8.0 if scale_px is None else float(scale_px)
    if not np.isfinite(scale) or scale < 1.0:
        raise ValueError(f"scale_px must be a finite number of texels >= 1; got {scale_px!r}")
    rows, cols = np.mgrid[0:height, 0:width].astype(np.float32)

    if kind == "checkerboard":
        cell_r, cell_c = (rows // scale).astype(np.int64), (cols // scale).astype(np.int64)
        n_r, n_c = int(cell_r.max()) + 1, int(cell_c.max()) + 1
        jitter = rng.uniform(-0.1, 0.1, size=(n_r, n_c)).astype(np.float32)
        base = np.where((cell_r + cell_c) % 2 == 0, np.float32(0.15), np.float32(0.85))
        out = base + jitter[cell_r, cell_c]
    elif kind in ("rectangles", "blobs"):
        out = np.full((height, width), rng.uniform(0.2, 0.8), dtype=np.float32)
        n_shapes = int(np.clip(4.0 * height * width / scale**2, 8, 20000))
        sizes = scale * np.exp(rng.uniform(np.log(0.25), np.log(2.0), size=(n_shapes, 2)))
        centres = rng.uniform(0.0, 1.0, size=(n_shapes, 2)) * [width, height]
        values = rng.uniform(0.0, 1.0, size=n_shapes)
        angles = rng.uniform(0.0, 180.0, size=n_shapes)
        for (cx, cy), (sw, sh), value, angle in zip(centres, sizes, values, angles):  # loop over shapes, not pixels
            if kind == "rectangles":
                x0, x1 = int(max(cx - sw / 2, 0)), int(min(cx + sw / 2, width))
                y0, y1 = int(max(cy - sh / 2, 0)), int(min(cy + sh / 2, height))
                out[y0:y1, x0:x1] = value
            else:
                cv2.ellipse(out, ((float(cx), float(cy)), (float(sw), float(sh)), float(angle)), float(value), -1)
    elif kind == "value_noise":
        out = _normalise(_value_noise(rng, (height, width), scale))
    elif kind == "fractal_noise":
        out = _normalise(_fractal_noise(rng, (height, width), 2.0 * scale))
    elif kind == "stripes":
        theta = rng.uniform(0.0, np.pi)
        phase = rng.uniform(0.0, 2.0 * np.pi)
        along = cols * np.float32(np.cos(theta)) + rows * np.float32(np.sin(theta))
        wave = np.tanh(np.float32(4.0) * np.sin(np.float32(2.0 * np.pi / scale) * along + np.float32(phase)))
        noise = _fractal_noise(rng, (height, width), scale, persistence=0.5)
        out = np.float32(0.5) + np.float32(0.4) * wave + np.float32(0.1) * noise / max(float(np.abs(noise).max()), 1e-6)
    else:  # tiles
        panel_r, panel_c = (rows // scale).astype(np.int64), (cols // scale).astype(np.int64)
        n_r, n_c = int(panel_r.max()) + 1, int(panel_c.max()) + 1
        brightness = rng.uniform(0.35, 0.9, size=(n_r, n_c)).astype(np.float32)
        grout_px = max(1.0, 0.06 * scale)
        in_grout = ((rows % scale) < grout_px) | ((cols % scale) < grout_px)
        noise = _fractal_noise(rng, (height, width), scale / 2.0, persistence=0.5)
        out = brightness[panel_r, panel_c] * (np.float32(1.0) + np.float32(0.25) * noise)
        out = np.where(in_grout, np.float32(0.08), out)
    return np.ascontiguousarray(np.clip(out, 0.0, 1.0), dtype=np.float32)


# ---------------------------------------------------------------------------------------------- aerial terrain
def _split_fields(rng: np.random.Generator, x0: float, y0: float, x1: float, y1: float, min_px: float,
                  max_px: float, out: list[tuple[float, float, float, float]]) -> None:
    """Append to ``out`` the rectangles of a random k-d subdivision of [x0, x1] x [y0, y1] (farm-field layout)."""
    stack = [(x0, y0, x1, y1)]
    while stack:
        a0, b0, a1, b1 = stack.pop()
        w, h = a1 - a0, b1 - b0
        too_big = max(w, h) > max_px
        can_split = max(w, h) > 2.0 * min_px
        if can_split and (too_big or rng.random() < 0.5):
            if w >= h:  # split the longer side at a random fraction
                cut = a0 + w * rng.uniform(0.3, 0.7)
                stack += [(a0, b0, cut, b1), (cut, b0, a1, b1)]
            else:
                cut = b0 + h * rng.uniform(0.3, 0.7)
                stack += [(a0, b0, a1, cut), (a0, cut, a1, b1)]
        else:
            out.append((a0, b0, a1, b1))


def aerial_terrain_texture(size_px: int = 4096, seed: int | np.random.Generator = 0,
                           metres_per_pixel: float = 0.75) -> np.ndarray:
    """Return a procedural aerial view of farmland (float32 (size_px, size_px) linear intensity in [0.02, 1]).

    Built at a known ground resolution so that features have physical sizes at several scales: fields of
    30-250 m (k-d subdivision with wobbly borders, dark hedges along half of them), each with its own albedo
    and texture (ploughed rows of 2.5-8 m period at a random heading, meadows with 1-3 m bushes, or woodland
    of 2-6 m tree crowns); fractal detail down to ~2 texels everywhere; roads 4-10 m wide crossing the map;
    villages of buildings (8-30 m, bright or dark roofs) with cast shadows. A 240 x 180 camera at 250 m
    altitude (~1.2 m per pixel) therefore sees texture everywhere. The result is cached per arguments and
    returned read-only.

    Args:
        size_px: width = height of the texture in texels (>= 64).
        seed: int seed or ``numpy.random.Generator`` (a Generator disables the cache).
        metres_per_pixel: ground size of one texel in metres (> 0).

    >>> tex = aerial_terrain_texture(256, seed=0, metres_per_pixel=2.0)
    >>> tex.shape, tex.dtype, bool(tex.std() > 0.05)
    ((256, 256), dtype('float32'), True)
    """
    if isinstance(size_px, (bool, np.bool_)) or not isinstance(size_px, (int, np.integer)) or size_px < 64:
        raise ValueError(f"size_px must be an int >= 64; got {size_px!r}")
    if not (isinstance(metres_per_pixel, (int, float, np.floating)) and np.isfinite(metres_per_pixel)
            and metres_per_pixel > 0):
        raise ValueError(f"metres_per_pixel must be a positive finite number; got {metres_per_pixel!r}")
    if isinstance(seed, np.random.Generator):
        texture = _aerial_terrain(int(size_px), seed, float(metres_per_pixel))
        texture.setflags(write=False)
        return texture
    _as_rng(seed)  # validates the seed
    return _aerial_terrain_cached(int(size_px), int(seed), float(metres_per_pixel))


@lru_cache(maxsize=2)
def _aerial_terrain_cached(size_px: int, seed: int, metres_per_pixel: float) -> np.ndarray:
    texture = _aerial_terrain(size_px, np.random.default_rng(seed), metres_per_pixel)
    texture.setflags(write=False)
    return texture


def _aerial_terrain(size: int, rng: np.random.Generator, mpp: float) -> np.ndarray:
    """Build the aerial terrain (see :func:`aerial_terrain_texture`)."""
    px = 1.0 / mpp  # texels per metre

    # 1. fields: k-d subdivision in texels; hedges (dark 2-4 m lines) on about half of the field borders;
    #    then wobbly borders through a smooth displacement field (cv2.remap, nearest neighbour)
    fields: list[tuple[float, float, float, float]] = []
    _split_fields(rng, 0.0, 0.0, float(size), float(size), 30.0 * px, 250.0 * px, fields)
    labels = np.zeros((size, size), dtype=np.float32)
    hedges = np.zeros((size, size), dtype=np.float32)
    for k, (a0, b0, a1, b1) in enumerate(fields):  # loop over fields, not pixels
        labels[int(b0) : int(np.ceil(b1)), int(a0) : int(np.ceil(a1))] = k
        if rng.random() < 0.5:
            thickness = max(1, int(round(rng.uniform(2.0, 4.0) * px)))
            cv2.rectangle(hedges, (int(a0), int(b0)), (int(a1), int(b1)), 1.0, thickness)
    wobble = 12.0 * px  # border wobble amplitude, metres -> texels
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float32)
    map_x = cols + np.float32(wobble) * _value_noise(rng, (size, size), 80.0 * px)
    map_y = rows + np.float32(wobble) * _value_noise(rng, (size, size), 80.0 * px)
    labels = cv2.remap(labels, map_x, map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REFLECT).astype(np.int64)
    hedges = cv2.remap(hedges, map_x, map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REFLECT)
    del map_x, map_y

    # 2. per-field albedo and texture: 0 meadow (bushes), 1 ploughed rows, 2 woodland (tree crowns)
    n_fields = len(fields)
    albedo = rng.uniform(0.08, 0.45, size=n_fields).astype(np.float32)
    kind = rng.choice(3, size=n_fields, p=[0.45, 0.4, 0.15])
    heading = rng.uniform(0.0, np.pi, size=n_fields).astype(np.float32)
    period = (rng.uniform(2.5, 8.0, size=n_fields) * px).astype(np.float32)
    phase = rng.uniform(0.0, 2.0 * np.pi, size=n_fields).astype(np.float32)
    kind_px = kind[labels]

    # fields with fBm detail from 40 m down to 2 texels: I = albedo (1 + 0.45 fbm)
    detail = _fractal_noise(rng, (size, size), 40.0 * px, smallest_px=2.0, persistence=0.85)
    detail /= max(float(np.abs(detail).max()), 1e-6)
    image = albedo[labels] * (np.float32(1.0) + np.float32(0.45) * detail)
    del detail

    # ploughed rows: I *= 1 + 0.35 sin(2 pi (x cos h + y sin h) / period + phase)
    along = cols * np.cos(heading)[labels] + rows * np.sin(heading)[labels]
    rows_wave = np.sin(np.float32(2.0 * np.pi) * along / period[labels] + phase[labels])
    image *= np.where(kind_px == 1, np.float32(1.0) + np.float32(0.35) * rows_wave, np.float32(1.0))
    del along, rows_wave, rows, cols

    # meadows: bushes and rocks, blobs of 1-3 m where a fine noise exceeds a per-field threshold
    spots = _value_noise(rng, (size, size), max(2.0, 2.5 * px))
    threshold = rng.uniform(0.12, 0.3, size=n_fields).astype(np.float32)
    bright = rng.random(n_fields) < 0.3
    spot_value = np.where(bright, np.float32(1.8), np.float32(0.35)).astype(np.float32)
    in_spot = (kind_px == 0) & (spots > threshold[labels])
    image = np.where(in_spot, image * spot_value[labels], image)
    del spots, in_spot

    # woodland: dark tree crowns (2-6 m) scattered in woodland fields, drawn on a crown mask
    crowns = np.zeros((size, size), dtype=np.float32)
    for k in np.flatnonzero(kind == 2):
        a0, b0, a1, b1 = fields[k]
        n_trees = int((a1 - a0) * (b1 - b0) / (5.0 * px) ** 2)
        xs, ys = rng.uniform(a0, a1, n_trees), rng.uniform(b0, b1, n_trees)
        radii = np.maximum(1, (rng.uniform(1.0, 3.0, n_trees) * px).astype(int))
        shades = rng.uniform(0.4, 1.0, n_trees)
        for x, y, r, shade in zip(xs, ys, radii, shades):  # loop over trees, not pixels
            cv2.circle(crowns, (int(x), int(y)), int(r), float(shade), -1)
    image = np.where((kind_px == 2) & (crowns > 0), np.float32(0.04) + np.float32(0.08) * crowns, image)
    image = np.where(hedges > 0, np.float32(0.05) * (np.float32(1.0) + image), image)  # hedges: dark lines
    del crowns, kind_px, labels, hedges

    # 3. roads: a few long polylines across the map, 4-10 m wide, with darker shoulders
    n_roads = max(2, int(round(size * mpp / 600.0)))
    for _ in range(n_roads):
        # start on a random edge, head roughly across the map, bend gently (length ~2 map sizes)
        edge = int(rng.integers(4))
        along_edge = rng.uniform(0.1, 0.9) * size
        start = [np.array([0.0, along_edge]), np.array([size, along_edge]),
                 np.array([along_edge, 0.0]), np.array([along_edge, size])][edge]
        direction = [0.0, np.pi, 0.5 * np.pi, -0.5 * np.pi][edge] + rng.uniform(-0.5, 0.5)
        points = [start]
        for _ in range(12):
            direction += rng.normal(0.0, 0.2)
            points.append(points[-1] + (size / 6.0) * np.array([np.cos(direction), np.sin(direction)]))
        poly = np.array(points)
        width_px = max(2, int(rng.uniform(4.0, 10.0) * px))
        pts = np.round(poly).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(image, [pts], False, 0.03, thickness=width_px + max(2, int(3 * px)), lineType=cv2.LINE_8)
        cv2.polylines(image, [pts], False, float(rng.uniform(0.25, 0.6)), thickness=width_px, lineType=cv2.LINE_8)

    # 4. villages: clusters of buildings (rotated rectangles) with a shadow cast away from the sun
    sun = np.array([np.cos(0.7), np.sin(0.7)])
    n_villages = max(1, int(round((size * mpp / 1000.0) ** 2 * 1.5)))
    for _ in range(n_villages):
        centre = rng.uniform(0.1 * size, 0.9 * size, 2)
        for _ in range(int(rng.integers(10, 40))):
            pos = centre + rng.normal(0.0, 60.0 * px, 2)
            w, h = rng.uniform(8.0, 30.0, 2) * px
            angle = rng.uniform(0.0, 180.0)
            corners = cv2.boxPoints(((float(pos[0]), float(pos[1])), (float(w), float(h)), float(angle)))
            shadow = corners + (rng.uniform(3.0, 10.0) * px) * sun
            hull = cv2.convexHull(np.round(np.concatenate([corners, shadow])).astype(np.int32))
            cv2.fillConvexPoly(image, hull, 0.02)  # shadow: hull of the footprint and its displaced copy
            roof = float(rng.choice([rng.uniform(0.05, 0.12), rng.uniform(0.5, 0.9)]))
            cv2.fillConvexPoly(image, np.round(corners).astype(np.int32), roof)
            if roof > 0.3:  # ridge line: two roof halves of different brightness
                mid = 0.5 * (corners[0] + corners[1]), 0.5 * (corners[2] + corners[3])
                half = np.array([corners[0], mid[0], mid[1], corners[3]])
                cv2.fillConvexPoly(image, np.round(half).astype(np.int32), roof * 0.7)

    return np.ascontiguousarray(np.clip(image, 0.02, 1.0), dtype=np.float32)
