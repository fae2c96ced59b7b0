"""write_png: an 8-bit PNG from a numpy image, in pure Python (zlib), so
that outcore.render's images can be saved without an imaging library.

Grey (H, W), RGB (H, W, 3) or RGBA (H, W, 4) uint8; rows top to bottom, no
filter, one deflate stream. Written under a hidden temporary name beside the
file and renamed into place, so a failed write leaves any earlier file
whole (as the C++ tools write their outputs).

Thread-safety: pure function (writes only its own files).
"""

from __future__ import annotations

import os
import secrets
import struct
import zlib
from pathlib import Path

import numpy as np

__all__ = ["write_png"]

_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_COLOUR_TYPES = {1: 0, 3: 2, 4: 6}  # channels -> PNG colour type (grey, RGB, RGBA)


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_bytes(image) -> bytes:
    """The PNG file of `image` (see write_png) as bytes."""
    a = np.asarray(image)
    if a.dtype != np.uint8:
        raise ValueError(f"image must be uint8, got dtype {a.dtype}")
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[2] not in _COLOUR_TYPES or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"image must have shape (H, W), (H, W, 3) or (H, W, 4) with H, W >= 1, got {np.shape(image)}")
    height, width, channels = a.shape
    if height >= 2**31 or width >= 2**31:
        raise ValueError(f"image of {width} x {height} pixels is beyond PNG's 2^31 - 1")
    header = struct.pack(">IIBBBBB", width, height, 8, _COLOUR_TYPES[channels], 0, 0, 0)
    # Each row starts with its filter type, 0 (none).
    rows = np.zeros((height, 1 + width * channels), dtype=np.uint8)
    rows[:, 1:] = np.ascontiguousarray(a).reshape(height, width * channels)
    return _SIGNATURE + _chunk(b"IHDR", header) + _chunk(b"IDAT", zlib.compress(rows.tobytes(), 6)) + _chunk(b"IEND", b"")


def write_png(path, image) -> None:
    """Writes `image` ((H, W), (H, W, 3) or (H, W, 4) uint8, row 0 at the
    top) to `path` as a PNG. Raises ValueError for another dtype or shape."""
    data = png_bytes(image)
    target = Path(path)
    temporary = target.resolve().parent / f".{target.name}.{os.getpid()}.{secrets.token_hex(6)}.tmp"
    # Mode 0666 less the umask, as for any new file (mkstemp would make it 0600).
    fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o666)
    try:
        with os.fdopen(fd, "wb") as out:
            out.write(data)
        os.replace(temporary, target)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
