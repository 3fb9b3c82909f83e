"""Height fields: a regular grid of heights, bilinear sampling, and two ways to make one.

``heights[row, col]`` is the height at x = origin[0] + col·spacing, z = origin[1] + row·spacing (row index = z,
column index = x), in the frame of whatever places the field (world space when nothing transforms it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from engine.images import decode_image, image_header

__all__ = ["HeightField", "MAX_HEIGHTMAP_SIDE", "inspect_heightmap", "load_heightmap_png", "midpoint_displacement"]

F64 = NDArray[np.float64]


@dataclass
class HeightField:
    """A grid of float64 heights with uniform ``spacing``; ``origin`` is the (x, z) of ``heights[0, 0]``.

    Sampling outside the grid (:meth:`height_at`, :meth:`normal_at`) clamps to the border: the surface continues
    flat-extruded from its edges, for what follows or stands on the ground (placement, terrain following). As a
    solid (:meth:`solid_distance`, a height-field Collider) the field is finite: the column below its surface over
    its footprint (:meth:`bounds`, edges included), as Bullet's and PhysX's height fields are, and nothing beside it.
    """

    heights: F64
    spacing: float = 1.0
    origin: F64 = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self) -> None:
        self.heights = np.array(self.heights, dtype=np.float64)
        if self.heights.ndim != 2 or min(self.heights.shape) < 2:
            raise ValueError(f"HeightField.heights must be a 2D grid of at least 2x2, got shape {self.heights.shape}")
        self.spacing = float(self.spacing)
        if not self.spacing > 0.0:
            raise ValueError(f"HeightField.spacing must be > 0, got {self.spacing}")
        self.origin = np.array(self.origin, dtype=np.float64)
        if self.origin.shape != (2,):
            raise ValueError(f"HeightField.origin must be (x, z), got shape {self.origin.shape}")

    @property
    def size(self) -> F64:
        """Extent in world units along (x, z): ((cols - 1)·spacing, (rows - 1)·spacing)."""
        rows, cols = self.heights.shape
        return np.array([(cols - 1) * self.spacing, (rows - 1) * self.spacing])

    @property
    def height_range(self) -> tuple[float, float]:
        """(min, max) of the heights: the vertical extent of the surface."""
        return float(self.heights.min()), float(self.heights.max())

    def height_at(self, x: ArrayLike, z: ArrayLike) -> F64:
        """Bilinear interpolation of the four surrounding samples, clamped at the borders; any broadcast shape.

        Outside the footprint this is the height of the nearest border point, not a solid there: see
        :meth:`solid_distance` for what lies inside the field."""
        x, z = np.asarray(x, dtype=np.float64), np.asarray(z, dtype=np.float64)
        if x.shape != z.shape:
            x, z = np.broadcast_arrays(x, z)
        rows, cols = self.heights.shape
        gx = np.clip((x - self.origin[0]) / self.spacing, 0.0, cols - 1)
        gz = np.clip((z - self.origin[1]) / self.spacing, 0.0, rows - 1)
        c0 = np.minimum(gx.astype(np.int64), cols - 2)  # gx >= 0, so truncation is the floor
        r0 = np.minimum(gz.astype(np.int64), rows - 2)
        tx, tz = gx - c0, gz - r0
        flat = self.heights.reshape(-1)  # a view of the contiguous grid
        i = r0 * cols + c0  # flat gathers: one index array instead of a pair per corner
        h00, h01, h10, h11 = flat[i], flat[i + 1], flat[i + cols], flat[i + (cols + 1)]
        top = h00 + tx * (h01 - h00)
        bottom = h10 + tx * (h11 - h10)
        return top + tz * (bottom - top)

    def normal_at(self, x: ArrayLike, z: ArrayLike) -> F64:
        """Unit normal (..., 3) = normalize(-∂h/∂x, 1, -∂h/∂z), the slopes by central differences of the
        bilinear surface over ±spacing/2 (one-sided at the borders; outside the grid, the normal of the nearest
        border point)."""
        x, z = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(z, dtype=np.float64))
        (x_lo, x_hi), (z_lo, z_hi) = self.bounds()
        x, z = np.clip(x, x_lo, x_hi), np.clip(z, z_lo, z_hi)
        e = 0.5 * self.spacing
        xa, xb = np.maximum(x - e, x_lo), np.minimum(x + e, x_hi)
        za, zb = np.maximum(z - e, z_lo), np.minimum(z + e, z_hi)
        dhdx = (self.height_at(xb, z) - self.height_at(xa, z)) / (xb - xa)
        dhdz = (self.height_at(x, zb) - self.height_at(x, za)) / (zb - za)
        n = np.stack([-dhdx, np.ones_like(dhdx), -dhdz], axis=-1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def solid_distance(self, x: ArrayLike, y: ArrayLike, z: ArrayLike) -> F64:
        """Signed distance to the field as a solid, the column below the surface over the footprint; negative
        inside, any broadcast shape.

        Over the footprint (its edges included): the vertical gap y − h(x, z). Beside it: the distance to the
        column's point straight across the footprint's border, √(g_x² + u² + g_z²), with g_x, g_z ≥ 0 the
        horizontal gaps to the footprint (one of them > 0) and u = max(y − h, 0) the height above the border's
        surface h (the clamped sample, :meth:`height_at`): the horizontal gap beside the walls (exact there), an
        upper bound above the border's height (as the vertical gap is over the footprint). Never negative beside
        the footprint, however low the point: a point under the surface's level but outside its extent is
        outside the solid. NaN x or z fail in :meth:`height_at`'s indexing.
        """
        x, y, z = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x, y, z)))
        (x_lo, x_hi), (z_lo, z_hi) = self.bounds()
        gap = y - self.height_at(x, z)
        gx = np.maximum(np.maximum(x_lo - x, x - x_hi), 0.0)
        gz = np.maximum(np.maximum(z_lo - z, z - z_hi), 0.0)
        up = np.maximum(gap, 0.0)
        with np.errstate(over="ignore"):  # a far point: an infinite distance, still positive
            beside = np.sqrt(gx * gx + up * up + gz * gz)
        return np.where((gx > 0.0) | (gz > 0.0), beside, gap)

    def bounds(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """Footprint ((x_min, x_max), (z_min, z_max)) covered by the samples."""
        size = self.size
        return (
            (float(self.origin[0]), float(self.origin[0] + size[0])),
            (float(self.origin[1]), float(self.origin[1] + size[1])),
        )


def midpoint_displacement(n: int, roughness: float, amplitude: float, rng: np.random.Generator) -> F64:
    """Diamond-square midpoint displacement (Fournier, Fussell & Carpenter 1982; Miller 1986) on a (2^n+1)² grid.

    Corners start uniform in [-amplitude, amplitude]. Each level halves the step s: the diamond step sets every
    square's centre to the mean of its 4 corners, the square step sets every edge midpoint to the mean of its
    (3 at the border, else 4) diamond neighbours, each plus a uniform displacement in [-a_k, a_k] with
    a_k = amplitude · roughness^k. So ``roughness`` r is the per-level amplitude ratio r = 2^(-H) (H the Hurst
    exponent): 0.5 is smooth, towards 1 rough. Python loops over the n levels only; each level is one set of
    array operations. Draw order is fixed (diamond, then row-aligned, then column-aligned edge points), so the
    grid is a pure function of the generator's state.
    """
    n, roughness, amplitude = int(n), float(roughness), float(amplitude)
    if n < 1:
        raise ValueError(f"midpoint_displacement n must be >= 1 (grid 2^n+1), got {n}")
    if not roughness > 0.0:
        raise ValueError(f"midpoint_displacement roughness must be > 0 (per-level amplitude ratio), got {roughness}")
    size = 2**n
    h = np.zeros((size + 1, size + 1))
    h[::size, ::size] = rng.uniform(-amplitude, amplitude, size=(2, 2))
    scale = amplitude
    step = size
    while step > 1:  # one iteration per level
        half = step // 2
        scale *= roughness
        cells = size // step
        # Diamond step: centre of each square = mean of its 4 corners + displacement.
        corners = (
            h[0:-1:step, 0:-1:step] + h[0:-1:step, step::step] + h[step::step, 0:-1:step] + h[step::step, step::step]
        )
        h[half::step, half::step] = 0.25 * corners + rng.uniform(-scale, scale, size=(cells, cells))
        centres = h[half::step, half::step]
        # Square step, edge midpoints on corner rows: left/right corners, centres above/below.
        total = h[0::step, 0:-1:step] + h[0::step, step::step]
        count = np.full(total.shape, 2.0)
        total[1:] += centres
        count[1:] += 1.0
        total[:-1] += centres
        count[:-1] += 1.0
        row_aligned = total / count + rng.uniform(-scale, scale, size=total.shape)
        # Square step, edge midpoints on centre rows: corners above/below, centres left/right.
        total = h[0:-1:step, 0::step] + h[step::step, 0::step]
        count = np.full(total.shape, 2.0)
        total[:, 1:] += centres
        count[:, 1:] += 1.0
        total[:, :-1] += centres
        count[:, :-1] += 1.0
        column_aligned = total / count + rng.uniform(-scale, scale, size=total.shape)
        h[0::step, half::step] = row_aligned
        h[half::step, 0::step] = column_aligned
        step = half
    return h


_GRAY_SCALES = {"L": 255.0, "LA": 255.0, "I;16": 65535.0, "I;16L": 65535.0, "I;16B": 65535.0, "I": 65535.0}
MAX_HEIGHTMAP_SIDE = 4097  # pixels per side (2^12 + 1): 134 MB of float64 heights at most


def inspect_heightmap(path: str | Path) -> tuple[str, tuple[int, int]]:
    """The image mode and (width, height) of a height map, read from its header only (cheap: no pixels decoded).

    Raises ``FileNotFoundError`` when the file does not exist and ``ValueError`` when it is not an image, not
    grayscale, smaller than 2×2 or larger than :data:`MAX_HEIGHTMAP_SIDE` per side, naming the path each time.
    """
    return image_header(path, "height map", _GRAY_SCALES, "8-bit ('L') or 16-bit ('I;16') grayscale, convert it "
                        "to grayscale first", 2, MAX_HEIGHTMAP_SIDE)


def load_heightmap_png(path: str | Path, height_scale: float = 1.0) -> F64:
    """Read an 8- or 16-bit grayscale image as heights in [0, height_scale]: height = value / max_value · scale.

    Image row = z (row index of the result), column = x. Raises ``FileNotFoundError`` when the file does not
    exist and ``ValueError`` when it is not a readable grayscale image of a sane size (see
    :func:`inspect_heightmap`), naming the path either way.
    """
    mode, _ = inspect_heightmap(path)
    values = decode_image(path, "height map", lambda image: np.asarray(
        image.getchannel("L") if mode == "LA" else image, dtype=np.float64))
    return values * (float(height_scale) / _GRAY_SCALES[mode])
