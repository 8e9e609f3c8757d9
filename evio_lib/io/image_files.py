"""Image files decoded with OpenCV, with the C decoders' own complaints caught instead of printed.

libpng and libjpeg write their warnings and errors straight to the process's stderr (file descriptor 2), around
Python: a damaged frame printed ``libpng error: IDAT: CRC error`` on the terminal before evio's one-line error.
:func:`read_image` points descriptor 2 at a temporary file while OpenCV decodes, then

* puts the decoder's text in the error when the image cannot be decoded
  (``images.txt frame 4: could not decode image frame_00000004.png (libpng error: IDAT: CRC error)``), and
* writes the text back to stderr when the image decoded (a warning is still seen, once, after the decode).

Threads take turns at the swap (a lock). Anything another thread writes to descriptor 2 during a decode (about a
millisecond) is written back after it, once.
"""
from __future__ import annotations

import os
import sys
import tempfile
import threading
from pathlib import Path

import cv2
import numpy as np

__all__ = ["read_image", "decoder_note"]

#: Held while descriptor 2 points at a temporary file (threads decoding at once take turns).
_DESCRIPTOR_2 = threading.Lock()


def read_image(path: str | Path, flags: int = cv2.IMREAD_UNCHANGED) -> tuple[np.ndarray | None, str]:
    """Return (the image of ``cv2.imread(path, flags)`` or None, what the C decoder printed, stripped).

    >>> import tempfile, os
    >>> png = bytearray(cv2.imencode(".png", np.zeros((4, 4), np.uint8))[1].tobytes())
    >>> png[20] ^= 0xFF  # a bit error in the header chunk: its CRC no longer matches
    >>> path = os.path.join(tempfile.mkdtemp(), "broken.png")
    >>> _ = open(path, "wb").write(png)
    >>> read_image(path)
    (None, 'libpng error: IHDR: CRC error')
    """
    try:
        sys.stderr.flush()
    except (AttributeError, OSError, ValueError):
        pass
    with _DESCRIPTOR_2:  # one swap at a time: a second thread would save the first one's file as "stderr"
        try:
            caught = tempfile.TemporaryFile()
        except OSError:  # no temporary folder: decode without catching
            return cv2.imread(str(path), flags), ""
        with caught:
            try:
                saved = os.dup(2)
            except OSError:  # no descriptor 2 (a daemon): nothing is printed anyway
                return cv2.imread(str(path), flags), ""
            os.dup2(caught.fileno(), 2)
            try:
                image = cv2.imread(str(path), flags)
            finally:
                os.dup2(saved, 2)
                os.close(saved)
            caught.seek(0)
            text = caught.read().decode("utf-8", errors="replace").strip()
    if text and image is not None:
        print(text, file=sys.stderr)
    # OpenCV's own log lines ("[ WARN:0@0.05] global loadsave.cpp ... can't open/read file") say less than the reader
    text = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("[ WARN"))
    return image, text.strip()


def decoder_note(text: str) -> str:
    """Return `` (TEXT's lines joined by '; ')`` for an error message, or '' when the decoder said nothing."""
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return f" ({'; '.join(lines)})" if lines else ""
