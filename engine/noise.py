"""Seeded, vectorized improved Perlin noise (Ken Perlin, "Improving Noise", SIGGRAPH 2002).

One implementation for the whole engine. Every call works on numpy arrays of any broadcastable shape (or
scalars), computes in float64 and returns float64 of the broadcast shape. Only ``+ - * /`` and ``floor`` are
used, so values are bit-identical across CPUs for the same seed.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["PerlinNoise"]

# The 16-entry gradient table of Perlin 2002, indexed by ``hash & 15``: the 12 edge midpoints of a cube, with
# (1,1,0), (-1,1,0), (0,-1,1), (0,-1,-1) repeated so the index is a cheap bit mask.
_GRADIENTS = np.array(
    [
        [1, 1, 0], [-1, 1, 0], [1, -1, 0], [-1, -1, 0],
        [1, 0, 1], [-1, 0, 1], [1, 0, -1], [-1, 0, -1],
        [0, 1, 1], [0, -1, 1], [0, 1, -1], [0, -1, -1],
        [1, 1, 0], [0, -1, 1], [-1, 1, 0], [0, -1, -1],
    ],
    dtype=np.float64,
)
_GRADIENTS.setflags(write=False)


def _fade(t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Quintic interpolant 6t^5 - 15t^4 + 10t^3 (Perlin 2002, eq. 2): zero 1st and 2nd derivative at 0 and 1."""
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def _lerp(t: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    return a + t * (b - a)


def _split(v: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Lattice cell index (wrapped to 0..255) and the fractional position inside the cell."""
    floor = np.floor(v)
    return floor.astype(np.int64) & 255, v - floor


class PerlinNoise:
    """Improved Perlin gradient noise with its own permutation table.

    The permutation of 0..255 is drawn from ``np.random.Generator(np.random.PCG64(seed))`` and doubled to 512
    entries, as in Perlin's reference code. The noise is 0 at every integer lattice point, C2-continuous, and
    lies roughly in [-1, 1]. Instances are immutable after construction.
    """

    def __init__(self, seed: int = 0) -> None:
        self.seed = int(seed)
        permutation = np.random.Generator(np.random.PCG64(self.seed)).permutation(256).astype(np.int64)
        self._perm = np.concatenate([permutation, permutation])
        self._perm.setflags(write=False)
        # the gradient of each hash h, _GRADIENTS[perm[h] & 15], one table per component: three gathers from
        # 512-entry tables instead of a permutation gather and a row gather of the (16, 3) table (same values)
        self._grad = tuple(np.ascontiguousarray(_GRADIENTS[self._perm & 15, axis]) for axis in range(3))

    def noise3(self, x: ArrayLike, y: ArrayLike, z: ArrayLike) -> NDArray[np.float64]:
        """3D improved Perlin noise (Perlin 2002): hash the 8 cell corners through the permutation, dot each
        corner's gradient ``_GRADIENTS[hash & 15]`` with the offset to the point, blend with the quintic fade."""
        # per-axis terms on the inputs as given (broadcast lazily: a grid's axes stay 1-D until they meet)
        x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
        shape = np.broadcast_shapes(x.shape, y.shape, z.shape)
        (xi, xf), (yi, yf), (zi, zf) = _split(x), _split(y), _split(z)
        u, v, w = _fade(xf), _fade(yf), _fade(zf)
        p = self._perm
        a, b = p[xi] + yi, p[xi + 1] + yi
        aa, ab, ba, bb = p[a] + zi, p[a + 1] + zi, p[b] + zi, p[b + 1] + zi

        gx, gy, gz = self._grad

        def grad(h: NDArray[np.int64], dx, dy, dz) -> NDArray[np.float64]:
            return gx.take(h) * dx + gy.take(h) * dy + gz.take(h) * dz

        x1, y1, z1 = xf - 1.0, yf - 1.0, zf - 1.0
        near = _lerp(
            v,
            _lerp(u, grad(aa, xf, yf, zf), grad(ba, x1, yf, zf)),
            _lerp(u, grad(ab, xf, y1, zf), grad(bb, x1, y1, zf)),
        )
        far = _lerp(
            v,
            _lerp(u, grad(aa + 1, xf, yf, z1), grad(ba + 1, x1, yf, z1)),
            _lerp(u, grad(ab + 1, xf, y1, z1), grad(bb + 1, x1, y1, z1)),
        )
        return np.broadcast_to(np.asarray(_lerp(w, near, far), dtype=np.float64), shape).copy()

    def noise2(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
        """2D improved Perlin noise: the z = 0 slice of :meth:`noise3` (Perlin 2002 with z = 0), evaluated with
        only the 4 corners that slice touches, so ``noise2(x, y) == noise3(x, y, 0)`` exactly."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        shape = np.broadcast_shapes(x.shape, y.shape)
        (xi, xf), (yi, yf) = _split(x), _split(y)
        u, v = _fade(xf), _fade(yf)
        p = self._perm
        a, b = p[xi] + yi, p[xi + 1] + yi
        aa, ab, ba, bb = p[a], p[a + 1], p[b], p[b + 1]  # + zi with zi = 0

        gx, gy, _ = self._grad

        def grad(h: NDArray[np.int64], dx, dy) -> NDArray[np.float64]:
            return gx.take(h) * dx + gy.take(h) * dy

        x1, y1 = xf - 1.0, yf - 1.0
        result = _lerp(
            v,
            _lerp(u, grad(aa, xf, yf), grad(ba, x1, yf)),
            _lerp(u, grad(ab, xf, y1), grad(bb, x1, y1)),
        )
        return np.broadcast_to(np.asarray(result, dtype=np.float64), shape).copy()

    def fbm3(
        self,
        x: ArrayLike,
        y: ArrayLike,
        z: ArrayLike,
        octaves: int = 4,
        lacunarity: float = 2.0,
        gain: float = 0.5,
    ) -> NDArray[np.float64]:
        """Fractional Brownian motion: sum_k gain^k * noise3(lacunarity^k * p), divided by sum_k gain^k so the
        result stays roughly in [-1, 1] whatever the octave count (Musgrave, "Texturing & Modeling", ch. 16)."""
        x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
        return self._fbm(lambda f: self.noise3(x * f, y * f, z * f), octaves, lacunarity, gain)

    def fbm2(
        self,
        x: ArrayLike,
        y: ArrayLike,
        octaves: int = 4,
        lacunarity: float = 2.0,
        gain: float = 0.5,
    ) -> NDArray[np.float64]:
        """2D fractional Brownian motion over :meth:`noise2`, normalized like :meth:`fbm3`."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        return self._fbm(lambda f: self.noise2(x * f, y * f), octaves, lacunarity, gain)

    @staticmethod
    def _fbm(octave, octaves: int, lacunarity: float, gain: float) -> NDArray[np.float64]:
        if int(octaves) < 1:
            raise ValueError(f"fbm octaves must be >= 1, got {octaves!r}")
        total, amplitude, frequency, norm = None, 1.0, 1.0, 0.0
        for _ in range(int(octaves)):  # loop over octaves, each vectorized over all points
            term = amplitude * octave(frequency)
            total = term if total is None else total + term
            norm += amplitude
            amplitude *= gain
            frequency *= lacunarity
        return np.asarray(total / norm, dtype=np.float64)
