"""Tests for engine.heightfield: bilinear sampling, normals, diamond-square and PNG loading."""

import numpy as np
import pytest
from PIL import Image

from engine.heightfield import HeightField, load_heightmap_png, midpoint_displacement


def test_height_at_grid_points_bilinear_and_clamped():
    heights = np.array([[0.0, 1.0, 2.0], [10.0, 11.0, 12.0]])  # row = z, col = x
    field = HeightField(heights=heights, spacing=2.0, origin=np.array([100.0, -4.0]))
    np.testing.assert_array_equal(field.size, [4.0, 2.0])
    xs = 100.0 + 2.0 * np.array([0, 1, 2, 0, 2])
    zs = -4.0 + 2.0 * np.array([0, 0, 0, 1, 1])
    np.testing.assert_array_equal(field.height_at(xs, zs), [0.0, 1.0, 2.0, 10.0, 12.0])
    np.testing.assert_allclose(field.height_at(101.0, -3.0), 5.5)  # centre of the first cell
    np.testing.assert_allclose(field.height_at(103.0, -3.5), 0.75 * 1.5 + 0.25 * 11.5)
    np.testing.assert_allclose(field.height_at([50.0, 500.0, 500.0], [-100.0, -100.0, 100.0]), [0.0, 2.0, 12.0])
    assert field.height_at(np.zeros((4, 5)), 0.0).shape == (4, 5)


def test_normal_at_tilted_plane_and_borders():
    xs = np.arange(9) * 0.5
    heights = 0.3 * xs[None, :] - 0.6 * xs[:, None]
    field = HeightField(heights=heights, spacing=0.5)
    rng = np.random.default_rng(0)
    x, z = rng.uniform(-1.0, 5.0, size=(2, 50))  # includes border and outside points
    normal = field.normal_at(x, z)
    assert normal.shape == (50, 3)
    expected = np.array([-0.3, 1.0, 0.6]) / np.linalg.norm([-0.3, 1.0, 0.6])
    np.testing.assert_allclose(normal, np.broadcast_to(expected, (50, 3)), atol=1e-12)


def test_normal_at_bump_points_away_from_peak():
    heights = np.zeros((5, 5))
    heights[2, 2] = 1.0
    field = HeightField(heights=heights, spacing=1.0)
    n = field.normal_at(np.array([1.5, 2.5, 2.0, 2.0]), np.array([2.0, 2.0, 1.5, 2.5]))
    assert n[0, 0] < 0 < n[1, 0] and n[2, 2] < 0 < n[3, 2]
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)


def test_heightfield_validation():
    with pytest.raises(ValueError, match="2x2"):
        HeightField(heights=np.zeros(5))
    with pytest.raises(ValueError, match="spacing"):
        HeightField(heights=np.zeros((2, 2)), spacing=0.0)


def test_midpoint_displacement_size_and_determinism():
    for n in (1, 3, 6):
        grid = midpoint_displacement(n, 0.5, 1.0, np.random.default_rng(0))
        assert grid.shape == (2**n + 1, 2**n + 1) and grid.dtype == np.float64
        assert np.all(np.isfinite(grid))
    a = midpoint_displacement(6, 0.6, 2.0, np.random.default_rng(123))
    b = midpoint_displacement(6, 0.6, 2.0, np.random.default_rng(123))
    c = midpoint_displacement(6, 0.6, 2.0, np.random.default_rng(124))
    np.testing.assert_array_equal(a, b)
    assert np.mean(a != c) > 0.9


def test_midpoint_displacement_is_averaging_plus_bounded_offsets():
    rng = np.random.default_rng(1)
    grid = midpoint_displacement(1, 0.5, 1.0, rng)
    corners = grid[::2, ::2]
    assert np.all(np.abs(corners) <= 1.0)
    # Diamond step: the centre is the mean of the corners, displaced by at most amplitude·roughness.
    assert abs(grid[1, 1] - corners.mean()) <= 0.5
    # Square step on the border: mean of 2 corners and the centre, displaced by at most 0.5.
    assert abs(grid[0, 1] - (grid[0, 0] + grid[0, 2] + grid[1, 1]) / 3.0) <= 0.5
    zero = midpoint_displacement(4, 0.5, 0.0, rng)
    np.testing.assert_array_equal(zero, 0.0)


def test_every_level_is_neighbour_mean_plus_bounded_displacement():
    """Scalar check of the diamond-square rules on the final grid: each point set at the level with step s
    differs from the mean of its (coarser, never rewritten) neighbours by at most amplitude·roughness^level."""
    n, roughness, amplitude = 4, 0.5, 1.0
    grid = midpoint_displacement(n, roughness, amplitude, np.random.default_rng(2))
    size = 2**n
    step, level, exceeded_half = size, 1, False
    while step > 1:
        half, bound = step // 2, amplitude * roughness**level
        for r in range(half, size, step):
            for c in range(half, size, step):
                mean = np.mean([grid[r - half, c - half], grid[r - half, c + half],
                                grid[r + half, c - half], grid[r + half, c + half]])
                assert abs(grid[r, c] - mean) <= bound + 1e-12
                exceeded_half |= abs(grid[r, c] - mean) > 0.5 * bound
        for r in range(0, size + 1, half):
            for c in range((r + half) % step, size + 1, step):
                neighbours = [grid[rr, cc] for rr, cc in ((r - half, c), (r + half, c), (r, c - half), (r, c + half))
                              if 0 <= rr <= size and 0 <= cc <= size]
                assert len(neighbours) == (4 if 0 < r < size and 0 < c < size else 3)
                assert abs(grid[r, c] - np.mean(neighbours)) <= bound + 1e-12
        step, level = half, level + 1
    assert exceeded_half  # the displacements are really there, not vanishing


def test_roughness_controls_fine_scale_variance():
    def fine_variance(roughness):
        grid = midpoint_displacement(7, roughness, 1.0, np.random.default_rng(9))
        return np.mean(np.diff(grid, axis=0) ** 2) + np.mean(np.diff(grid, axis=1) ** 2)

    smooth, medium, rough = fine_variance(0.4), fine_variance(0.6), fine_variance(0.85)
    assert smooth < medium < rough
    assert rough > 10 * smooth
    with pytest.raises(ValueError, match="roughness"):
        midpoint_displacement(3, 0.0, 1.0, np.random.default_rng(0))


def test_png_roundtrip_16_and_8_bit(tmp_path):
    values16 = np.array([[0, 65535, 1000], [30000, 12345, 65534]], dtype=np.uint16)
    path16 = tmp_path / "h16.png"
    Image.fromarray(values16).save(path16)
    heights = load_heightmap_png(path16, height_scale=50.0)
    assert heights.shape == (2, 3) and heights.dtype == np.float64
    np.testing.assert_allclose(heights, values16 / 65535.0 * 50.0, rtol=1e-12)

    values8 = np.array([[0, 128], [255, 7]], dtype=np.uint8)
    path8 = tmp_path / "h8.png"
    Image.fromarray(values8).save(path8)
    np.testing.assert_allclose(load_heightmap_png(str(path8), 2.0), values8 / 255.0 * 2.0, rtol=1e-12)


def test_png_errors_name_the_path(tmp_path):
    missing = tmp_path / "nope.png"
    with pytest.raises(FileNotFoundError, match="nope.png"):
        load_heightmap_png(missing, 1.0)
    junk = tmp_path / "junk.png"
    junk.write_text("not an image")
    with pytest.raises(ValueError, match="junk.png"):
        load_heightmap_png(junk, 1.0)
    rgb = tmp_path / "colour.png"
    Image.new("RGB", (4, 4)).save(rgb)
    with pytest.raises(ValueError, match="colour.png.*grayscale"):
        load_heightmap_png(rgb, 1.0)
