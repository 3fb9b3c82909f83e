"""Colour textures read from image files (PNG, JPEG) for materials such as a terrain's ground texture.

No GL here: a texture is decoded to a linear-light float array once, when its component is built, and the
renderer uploads it.  Image files store sRGB-encoded colour, so the values are decoded with the sRGB transfer
function (IEC 61966-2-1) before they multiply anything in the renderer's linear HDR colour.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from engine.images import decode_image, image_header

__all__ = ["MAX_TEXTURE_SIDE", "inspect_texture", "load_texture", "srgb_to_linear"]

MAX_TEXTURE_SIDE = 4096  # pixels per side: 64 MiB of RGBA8 at most, the size GL 3.3 guarantees a texture may have


def srgb_to_linear(values: NDArray[np.floating]) -> NDArray[np.float32]:
    """sRGB-encoded values in [0, 1] to linear light (the piecewise curve of IEC 61966-2-1)."""
    v = np.asarray(values, np.float64)
    linear = np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)
    return linear.astype(np.float32)


_MODES = ("1", "L", "LA", "P", "PA", "RGB", "RGBA", "RGBX", "CMYK", "YCbCr")  # 8 bits a channel: converted to RGB


def inspect_texture(path: str | Path) -> tuple[int, int]:
    """(width, height) of a texture image, read from its header only.  Raises ``FileNotFoundError`` when the file
    does not exist and ``ValueError`` when it is not an image, not 8 bits a channel, or larger than
    :data:`MAX_TEXTURE_SIDE` pixels a side, naming the path each time."""
    return image_header(path, "texture", _MODES, "8 bits a channel (RGB, RGBA, grey or palette), convert it to "
                        "8-bit RGB first", 1, MAX_TEXTURE_SIDE)[1]


def load_texture(path: str | Path) -> NDArray[np.float32]:
    """An image as linear RGB in [0, 1], shape (rows, columns, 3), row 0 the image's top row.  Grey and palette
    images are converted to RGB, alpha is dropped.  Errors as :func:`inspect_texture`, also for a file whose
    pixels cannot be decoded (a truncated PNG)."""
    inspect_texture(path)
    values = decode_image(path, "texture", lambda image: np.asarray(image.convert("RGB"), np.float64) / 255.0)
    return srgb_to_linear(values)
