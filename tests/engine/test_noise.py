"""Tests for engine.noise: improved Perlin noise (Perlin 2002) and its fBm sums."""

import math

import numpy as np
import pytest

from engine.noise import PerlinNoise


def _reference_noise3(perm: np.ndarray, x: float, y: float, z: float) -> float:
    """Scalar transcription of Perlin's 2002 reference code (bit-trick grad), for cross-checking."""

    def fade(t):
        return t * t * t * (t * (t * 6 - 15) + 10)

    def lerp(t, a, b):
        return a + t * (b - a)

    def grad(h, x, y, z):
        h &= 15
        u = x if h < 8 else y
        v = y if h < 4 else (x if h in (12, 14) else z)
        return (u if h & 1 == 0 else -u) + (v if h & 2 == 0 else -v)

    p = [int(v) for v in perm]
    X, Y, Z = math.floor(x) & 255, math.floor(y) & 255, math.floor(z) & 255
    x, y, z = x - math.floor(x), y - math.floor(y), z - math.floor(z)
    u, v, w = fade(x), fade(y), fade(z)
    A = p[X] + Y
    AA, AB = p[A] + Z, p[A + 1] + Z
    B = p[X + 1] + Y
    BA, BB = p[B] + Z, p[B + 1] + Z
    return lerp(
        w,
        lerp(v, lerp(u, grad(p[AA], x, y, z), grad(p[BA], x - 1, y, z)),
             lerp(u, grad(p[AB], x, y - 1, z), grad(p[BB], x - 1, y - 1, z))),
        lerp(v, lerp(u, grad(p[AA + 1], x, y, z - 1), grad(p[BA + 1], x - 1, y, z - 1)),
             lerp(u, grad(p[AB + 1], x, y - 1, z - 1), grad(p[BB + 1], x - 1, y - 1, z - 1))),
    )


@pytest.fixture
def points():
    rng = np.random.default_rng(7)
    return rng.uniform(-40.0, 40.0, size=(3, 20_000))


def test_matches_perlin_reference_code():
    noise = PerlinNoise(seed=3)
    perm = np.concatenate([np.random.Generator(np.random.PCG64(3)).permutation(256)] * 2)
    rng = np.random.default_rng(1)
    pts = rng.uniform(-300.0, 300.0, size=(200, 3))
    expected = [_reference_noise3(perm, *p) for p in pts]
    np.testing.assert_allclose(noise.noise3(pts[:, 0], pts[:, 1], pts[:, 2]), expected, rtol=0, atol=1e-12)


def test_zero_at_integer_lattice_points():
    noise = PerlinNoise(seed=11)
    grid = np.arange(-20, 21, dtype=np.float64)
    x, y, z = np.meshgrid(grid, grid, grid[::4], indexing="ij")
    assert np.all(noise.noise3(x, y, z) == 0.0)
    assert np.all(noise.noise2(x[..., 0], y[..., 0]) == 0.0)
    assert np.all(noise.fbm3(x, y, z, octaves=5) == 0.0)


def test_values_lie_roughly_in_unit_range_and_vary(points):
    noise = PerlinNoise(seed=5)
    for values in (noise.noise3(*points), noise.noise2(points[0], points[1])):
        assert np.abs(values).max() <= 1.1
        assert values.std() > 0.1
        assert values.max() > 0.5 and values.min() < -0.5
        assert abs(values.mean()) < 0.05
    assert np.abs(noise.fbm3(*points, octaves=6)).max() <= 1.1


def test_same_seed_same_values_different_seed_different(points):
    a, b, c = PerlinNoise(seed=42), PerlinNoise(seed=42), PerlinNoise(seed=43)
    np.testing.assert_array_equal(a.noise3(*points), b.noise3(*points))
    np.testing.assert_array_equal(a.fbm2(points[0], points[1]), b.fbm2(points[0], points[1]))
    assert np.mean(a.noise3(*points) != c.noise3(*points)) > 0.9


def test_continuity_small_step_small_change(points):
    noise = PerlinNoise(seed=9)
    h = 1e-5
    for delta in (np.array([h, 0, 0]), np.array([0, h, 0]), np.array([0, 0, h])):
        moved = points + delta[:, None]
        change = np.abs(noise.noise3(*moved) - noise.noise3(*points))
        assert change.max() < 10 * h
    change2 = np.abs(noise.noise2(points[0] + h, points[1] - h) - noise.noise2(points[0], points[1]))
    assert change2.max() < 10 * h


def test_broadcast_shapes_scalars_and_dtype():
    noise = PerlinNoise()
    x = np.linspace(0.0, 3.0, 5)
    y = np.linspace(0.0, 2.0, 4)
    z = np.linspace(0.0, 1.0, 3)
    out3 = noise.noise3(x[:, None, None], y[None, :, None], z[None, None, :])
    assert out3.shape == (5, 4, 3) and out3.dtype == np.float64
    assert noise.noise2(x[:, None], y[None, :]).shape == (5, 4)
    assert noise.fbm3(x[:, None], y[None, :], 0.5).shape == (5, 4)
    assert noise.fbm2(x[:, None], 0.3).shape == (5, 1)
    scalar = noise.noise3(0.3, 0.7, 1.1)
    assert scalar.shape == () and scalar.dtype == np.float64
    assert noise.noise2(np.float32(0.3), np.float32(0.7)).dtype == np.float64


def test_noise2_is_z_zero_slice_of_noise3(points):
    noise = PerlinNoise(seed=2)
    np.testing.assert_array_equal(noise.noise2(points[0], points[1]), noise.noise3(points[0], points[1], 0.0))


def test_fbm_octaves_are_normalized_sums():
    noise = PerlinNoise(seed=4)
    x, y, z = np.array([0.3, 1.7]), np.array([2.2, -0.4]), np.array([0.9, 5.5])
    np.testing.assert_array_equal(noise.fbm3(x, y, z, octaves=1), noise.noise3(x, y, z))
    expected = (noise.noise3(x, y, z) + 0.5 * noise.noise3(3 * x, 3 * y, 3 * z)) / 1.5
    np.testing.assert_allclose(noise.fbm3(x, y, z, octaves=2, lacunarity=3.0, gain=0.5), expected, atol=1e-15)
    expected2 = (noise.noise2(x, y) + 0.25 * noise.noise2(2 * x, 2 * y)) / 1.25
    np.testing.assert_allclose(noise.fbm2(x, y, octaves=2, gain=0.25), expected2, atol=1e-15)
    with pytest.raises(ValueError, match="octaves"):
        noise.fbm2(x, y, octaves=0)


def test_grid_axes_give_the_bits_of_the_full_grid():
    """Per-axis inputs are broadcast as late as possible (a grid's hashing runs on its (x, y) plane, not on
    every cell); the values must be those of the fully broadcast arrays, bit for bit."""
    n = PerlinNoise(11)
    ax = np.linspace(-2.3, 5.1, 17)
    x, y, z = ax[:, None, None], 1.7 * ax[None, :, None], -0.6 * ax[None, None, :]
    full = n.fbm3(*np.broadcast_arrays(x, y, z), octaves=3)
    lazy = n.fbm3(x, y, z, octaves=3)
    assert lazy.shape == (17, 17, 17) and lazy.flags.writeable and np.array_equal(lazy, full)
    assert np.array_equal(n.noise2(x[:, :, 0], y[:, :, 0]), n.noise2(*np.broadcast_arrays(x[:, :, 0], y[:, :, 0])))
