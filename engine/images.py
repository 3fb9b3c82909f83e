"""Image files read for assets (height maps, textures): the header check and the decode, with errors that name
the file.  Each asset kind says which image modes and sizes it takes (:mod:`engine.heightfield`,
:mod:`engine.textures`)."""

from __future__ import annotations

from collections.abc import Callable, Container
from pathlib import Path
from typing import TypeVar

from PIL import Image, UnidentifiedImageError

__all__ = ["decode_image", "image_header"]

T = TypeVar("T")
_UNREADABLE = (UnidentifiedImageError, Image.DecompressionBombError, OSError)


def image_header(path: str | Path, what: str, modes: Container[str], expected_mode: str, min_side: int,
                 max_side: int) -> tuple[str, tuple[int, int]]:
    """The image mode and (width, height) of the ``what`` (e.g. "height map") at ``path``, read from its header
    only (cheap: no pixels decoded).

    Raises ``FileNotFoundError`` when the file does not exist and ``ValueError`` when it is not an image, its mode
    is not in ``modes`` (the message says ``expected_mode``) or a side is outside [``min_side``, ``max_side``],
    naming the path each time."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} '{path}' not found")
    try:
        with Image.open(path) as image:
            mode, size = image.mode, image.size
    except _UNREADABLE as error:
        raise ValueError(f"{what} '{path}' is not a readable image: {error}") from None
    if mode not in modes:
        raise ValueError(f"{what} '{path}' has image mode {mode!r}; expected {expected_mode}")
    if min(size) < min_side or max(size) > max_side:
        raise ValueError(f"{what} '{path}' is {size[0]}×{size[1]} pixels; expected {min_side} to {max_side} pixels "
                         "per side")
    return mode, size


def decode_image(path: str | Path, what: str, convert: Callable[[Image.Image], T]) -> T:
    """``convert`` applied to the decoded image at ``path``; a file whose pixels cannot be decoded (a truncated
    PNG whose header reads) raises ``ValueError`` naming the ``what`` and the path."""
    try:
        with Image.open(path) as image:
            image.load()
            return convert(image)
    except _UNREADABLE as error:
        raise ValueError(f"{what} '{path}' is not a readable image: {error}") from None
