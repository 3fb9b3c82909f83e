"""Crawfis' tornado field (2.1, seeds/004): published formula, grid, frames and lookups."""

import numpy as np
import pytest

from systems.dust_devil.tornado import centre_line, crawfis_tornado, sample_wind, to_unit, wind_grid

# (x, y, z, t) -> v, worked by hand from the formula in the spec.  First row, step by step:
#   xc = 0.5 + 0.1 sin 0 = 0.5, yc = 0.5 + 0.1 cos 0 = 0.6, r = 0.1, r2 = 0.2, d = 0.1
#   s = |0.1 - 0.1| = 0 <= r2 -> 1;  z0 = 0.1 (0.1 - 0) = 0.01;  d = sqrt(0.01 + 0.0001) = 0.10049875621
#   s = (0.1 + 0.2 - 0.10049875621) / 0.10049875621 / (1 + 0) = 1.98511157043
#   v = (1.98511157 · (-0.1) + 0, -1.98511157 · 0 + 0.1 · (-0.1), 1.98511157 · 0.01)
HAND = [
    ((0.5, 0.5, 0.0, 0.0), (-0.1985111570432442, -0.01, 0.019851115704324428)),
    # |r - d| = 0.327 > r2 = 0.25: the "0.8 - s" branch; d z = 0.245 > 0.1 so z0 = 0 (no lift)
    ((0.9, 0.2, 0.5, 25.0), (0.054579215916289545, -0.0024548302885063107, 0.0)),
    ((0.2, 0.8, 0.9, 100.0), (0.07295829117493906, 0.19091677652951208, 0.0)),
    ((0.55, 0.45, 0.3, 7.0), (-0.16677876986543594, -0.1263870907556352, 0.012061793968772322)),
]


@pytest.mark.parametrize("point, expected", HAND)
def test_field_matches_published_formula(point, expected):
    x, y, z, t = point
    np.testing.assert_allclose(crawfis_tornado(x, y, z, t), expected, rtol=1e-12, atol=1e-15)


def test_field_magnitude_range():
    """The author's note: magnitudes range from 0 to about 0.4 over the unit cube."""
    g = np.linspace(0.0, 1.0, 41)
    v = crawfis_tornado(g[:, None, None], g[None, :, None], g[None, None, :], 0.0)
    mag = np.linalg.norm(v, axis=-1)
    assert 0.0 <= mag.min() < 0.05
    assert 0.25 < mag.max() <= 0.4


def test_centre_line_rotation_is_clockwise_from_above():
    """Rotating by +a moves the centre offset from the axis clockwise seen from +z (x towards -y)."""
    xc0, yc0 = centre_line(0.4, 3.0, 0.0)
    xc1, yc1 = centre_line(0.4, 3.0, np.radians(30.0))
    a, b = np.array([xc0 - 0.5, yc0 - 0.5]), np.array([xc1 - 0.5, yc1 - 0.5])
    assert a[0] * b[1] - a[1] * b[0] < 0.0  # negative z component of a x b: clockwise
    assert np.degrees(np.arccos(a @ b / np.linalg.norm(a) / np.linalg.norm(b))) == pytest.approx(30.0)
    # rotating the centre line rotates the whole field with it (the field is built around the centre)
    p = np.array([0.62, 0.41])
    c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    rot = np.array([[c, s], [-s, c]])
    q = 0.5 + rot @ (p - 0.5)
    v0 = crawfis_tornado(p[0], p[1], 0.4, 3.0)
    v1 = crawfis_tornado(q[0], q[1], 0.4, 3.0, np.radians(30.0))
    np.testing.assert_allclose(v1[:2], rot @ v0[:2], atol=1e-12)
    assert v1[2] == pytest.approx(v0[2])


def test_grid_maps_crawfis_axes_onto_the_box():
    """Grid [ix, iy (up), iz] holds Crawfis' (vx Sx, vz Sy, -vy Sz) at (ix, 1 - iz, iy) / (n - 1)."""
    size = (24.0, 30.0, 20.0)
    grid = wind_grid((9, 7, 5), size, 12.0, 0.4, 2.0)
    assert grid.shape == (9, 7, 5, 3)
    for ix, iy, iz in [(0, 0, 0), (3, 5, 1), (8, 6, 4), (4, 2, 2)]:
        v = crawfis_tornado(ix / 8, 1.0 - iz / 4, iy / 6, 12.0, 0.4)
        np.testing.assert_allclose(grid[ix, iy, iz], 2.0 * np.array([v[0] * 24, v[2] * 30, -v[1] * 20]),
                                   rtol=1e-12, atol=1e-14)


def test_swirl_is_clockwise_seen_from_above_in_engine_space():
    """The frame change is a proper rotation: Crawfis' clockwise swirl stays clockwise seen from +y."""
    size = np.array([20.0, 20.0, 20.0])
    grid = wind_grid((33, 9, 33), size, 0.0, 0.0, 1.0)
    centre = np.array([(0.5 - 0.5) * 20, 5.0, 0.0])
    xc, yc = centre_line(0.25, 0.0)
    centre[0], centre[2] = (xc - 0.5) * 20, (0.5 - yc) * 20
    ring = centre + np.array([[3.0, 0.0, 0.0], [0.0, 0.0, 3.0], [-3.0, 0.0, 0.0], [0.0, 0.0, -3.0]])
    v = sample_wind(grid, to_unit(ring, size), "trilinear")
    # angular momentum about +y: (r x v)_y = r_z v_x - r_x v_z ; clockwise seen from above means negative
    r = ring - centre
    assert np.all(r[:, 2] * v[:, 0] - r[:, 0] * v[:, 2] < 0.0)


def test_nearest_lookup_takes_the_nearest_grid_vector():
    rng = np.random.default_rng(4)
    grid = rng.normal(size=(5, 6, 7, 3))
    u = rng.random((200, 3))
    got = sample_wind(grid, u, "nearest")
    idx = np.rint(u * (np.array([5, 6, 7]) - 1)).astype(int)
    np.testing.assert_array_equal(got, grid[idx[:, 0], idx[:, 1], idx[:, 2]])
    # outside the unit cube the lookup clamps to the border
    np.testing.assert_array_equal(sample_wind(grid, np.array([[-0.3, 1.4, 0.0]]), "nearest"), grid[None, 0, 5, 0])


def test_trilinear_lookup_is_exact_on_grid_points_and_linear_between():
    rng = np.random.default_rng(5)
    i = np.arange(4, dtype=float)
    lin = lambda u: np.stack([2 * u[:, 0] - u[:, 1] + 0.5 * u[:, 2], u[:, 2], -u[:, 0]], axis=-1)  # noqa: E731
    gx, gy, gz = np.meshgrid(i / 3, i / 3, i / 3, indexing="ij")
    grid = lin(np.stack([gx, gy, gz], -1).reshape(-1, 3)).reshape(4, 4, 4, 3)
    u = rng.random((100, 3))
    np.testing.assert_allclose(sample_wind(grid, u, "trilinear"), lin(u), atol=1e-12)
    with pytest.raises(ValueError, match="lookup mode"):
        sample_wind(grid, u, "cubic")


def test_the_field_at_the_particles_nodes_is_the_grid_bit_for_bit():
    """Nearest lookups evaluate the formula at just the needed grid points when the particles are fewer than
    the grid's points; the values must be the grid's exactly (determinism does not depend on the path)."""
    from systems.dust_devil.tornado import WindField, wind_at_nodes

    resolution, size = (17, 13, 11), (24.0, 30.0, 20.0)
    grid = wind_grid(resolution, size, 37.5, 1.3, 1.7)
    rng = np.random.default_rng(9)
    nodes = np.stack([rng.integers(0, n, 500) for n in resolution], axis=-1)
    got = wind_at_nodes(resolution, size, 37.5, 1.3, 1.7, nodes)
    assert np.array_equal(got, grid[nodes[:, 0], nodes[:, 1], nodes[:, 2]])  # exact, not close

    u = rng.uniform(-0.1, 1.1, (300, 3))
    field = WindField(resolution, size, 37.5, 1.3, 1.7)
    v = field.sample(u, "nearest")
    needed = np.unique(np.rint(np.clip(u, 0, 1) * (np.array(resolution) - 1)) @ [13 * 11, 11, 1])
    assert field.evaluated == len(needed) < 300  # each needed grid point once, nothing else
    assert np.array_equal(v, sample_wind(grid, u, "nearest"))
    assert np.array_equal(field.sample(u, "nearest"), v) and field.evaluated == len(needed)  # known: no work
    assert np.array_equal(field.sample(u, "trilinear"), sample_wind(grid, u, "trilinear"))
    assert field.evaluated <= np.prod(resolution)
    assert np.array_equal(field.grid, grid) and field.evaluated == np.prod(resolution)
