"""The display grid (seeds/002 §3.2–3.5): upsampling, blobs (figure 2), noise, marching cubes, the ramp coordinate."""

import numpy as np
import pytest

from engine.noise import PerlinNoise
from systems.toon_smoke import simulate
from systems.toon_smoke.display import blob_axes, extract_isosurface, splat_blobs, splat_blobs_numpy, toon_coordinate
from systems.toon_smoke.grid import Geometry, upsample_linear
from tests.systems.toon_smoke.helpers import run_state, small


def test_upsampling_is_trilinear():
    """A linear field is reproduced exactly by the upsampling away from the clamped border."""
    n, k = 8, 2
    i, j, l = np.indices((n, n, n)).astype(np.float32)
    coarse = 0.5 * i - 0.25 * j + 0.125 * l
    fine = upsample_linear(coarse, k)
    fi, fj, fl = ((np.indices(fine.shape) + 0.5) / k - 0.5).astype(np.float32)
    expected = 0.5 * fi - 0.25 * fj + 0.125 * fl
    core = (slice(1, -1),) * 3
    assert fine.shape == (16, 16, 16)
    assert np.allclose(fine[core], expected[core], atol=1e-5)


def _blob_extent(density: np.ndarray, axis: int) -> int:
    """Number of cells along ``axis`` through the blob's centre with density > 0."""
    c = np.array(density.shape) // 2
    line = [slice(c[0], c[0] + 1), slice(c[1], c[1] + 1), slice(c[2], c[2] + 1)]
    line[axis] = slice(None)
    return int((density[tuple(line)] > 0).sum())


def test_blob_is_an_ellipsoid_stretched_along_the_velocity():
    """Figure 2: the blob is elongated along u by s and thinned across by √s (a/b = s^{3/2}), volume kept."""
    along, across = blob_axes(np.array([0.8]), np.array([2.0]), 0.3, 0.1, 0.0, 1.0, 0.5, 4.0)
    s = 1.0 + 0.5 * 2.0
    assert along[0] / across[0] == pytest.approx(s ** 1.5)
    assert along[0] * across[0] ** 2 == pytest.approx(0.1 ** 3)  # same volume as the sphere of radius R
    grid = np.zeros((41, 41, 41), np.float32)
    cell = 0.02
    splat_blobs(grid, np.array([[20.0, 20.0, 20.0]]), np.array([[1.0, 0.0, 0.0]]), along / cell, across / cell, 1.0)
    ex, ey, ez = (_blob_extent(grid, a) for a in range(3))
    assert ey == ez
    assert ex / ey == pytest.approx(s ** 1.5, rel=0.15)
    assert grid.max() == pytest.approx(1.0)  # the amplitude at the centre


def test_blob_radius_grows_with_density_and_is_capped():
    along, across = blob_axes(np.array([0.3, 0.8, 50.0]), np.zeros(3), 0.3, 0.1, 0.2, 0.25, 0.5, 2.0)
    assert np.allclose(along, across)  # no velocity: a sphere
    assert along[0] == pytest.approx(0.1) and along[1] == pytest.approx(0.2) and along[2] == pytest.approx(0.25)


def test_splat_matches_a_per_particle_reference():
    rng = np.random.default_rng(2)
    m = 30
    centres = rng.uniform(-1, 18, (m, 3))  # blob centres may lie up to a cell outside the grid
    dirs = rng.standard_normal((m, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    along = rng.uniform(1.0, 4.0, m)
    across = along / rng.uniform(1.0, 2.0, m)
    grid = np.zeros((18, 18, 18), np.float32)
    splat_blobs(grid, centres, dirs, along, across, 0.7)
    ref = np.zeros(grid.shape)
    idx = np.stack(np.indices(grid.shape), axis=-1).astype(np.float64)
    for c, d, a, b in zip(centres, dirs, along, across):  # reference loop, test only
        r = idx - c
        t = r @ d
        q = 1.0 - (t * t / a ** 2 + ((r * r).sum(-1) - t * t) / b ** 2)
        ref += 0.7 * np.where(q > 0, q, 0.0) ** 3
    assert np.allclose(grid, ref, atol=1e-4)


def _random_blobs(seed: int, m: int, reach: float):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-2.0, 34.0, (m, 3))  # some more than a cell outside the grid: skipped by both
    dirs = rng.standard_normal((m, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    along = rng.uniform(0.3, reach, m)
    return centres, dirs, along, along / rng.uniform(1.0, 2.0, m)


@pytest.mark.parametrize("seed, m, shape", [(3, 300, (32, 32, 32)), (4, 40, (20, 24, 28)), (6, 2, (36, 36, 36))])
def test_compiled_splat_equals_the_numpy_splat(seed, m, shape):
    """The kernel does the numpy code's float32 operations in its order (stencil products summed left to right in
    both, the offset from the rounded cell taken before any padding): the same bits, not just close."""
    blobs = _random_blobs(seed, m, 3.5)
    base = np.random.default_rng(seed).uniform(0.0, 1.0, shape).astype(np.float32)
    compiled, reference = base.copy(), base.copy()
    assert splat_blobs(compiled, *blobs, 0.9) == splat_blobs_numpy(reference, *blobs, 0.9)
    assert not np.array_equal(compiled, base)  # blobs were added
    assert np.array_equal(compiled, reference)
    again = base.copy()
    splat_blobs(again, *blobs, 0.9)
    assert np.array_equal(again, compiled)  # the same bits every time


def test_particles_add_blobs_only_above_the_threshold():
    cfg = small()
    state = run_state(cfg, 25)
    assert 0 < state.blob_count < cfg.particle_count
    high = run_state(small(particle_density_threshold=100.0, density_limit=200.0), 25)
    assert high.blob_count == 0


def test_noise_depends_on_position_alone():
    """§3.4: display density = noise(x) × (upsampled ρ + blobs); the factor is the engine's Perlin noise at x."""
    cfg = small(particle_count=0, obstacle_radius=0.0, noise_strength=0.5, noise_octaves=1)
    state = run_state(cfg, 10)
    geo = state.geometry
    x, y, z = np.broadcast_arrays(*geo.local_display_centres())
    expected = np.maximum(0.0, 1.0 + 0.5 * PerlinNoise(state.noise_seed).noise3(x / cfg.noise_scale,
                                                                                 y / cfg.noise_scale,
                                                                                 z / cfg.noise_scale))
    base = upsample_linear(state.density, geo.factor)
    assert np.allclose(state.display_density, np.minimum(base * expected, cfg.density_limit), atol=1e-5)
    first = state.noise_factor.copy()
    simulate.display_grid(cfg, state)
    assert np.array_equal(state.noise_factor, first)  # the same factor at every step


def _sphere_field(n: int, radius: float, cell: float):
    c = (np.arange(n) + 0.5) * cell - 0.5 * n * cell
    x, y, z = np.meshgrid(c, c, c, indexing="ij")
    return (radius - np.sqrt(x * x + y * y + z * z)).astype(np.float32), np.full(3, c[0])


def test_marching_cubes_on_a_sphere_is_watertight_outward_and_the_right_size():
    radius, cell = 0.7, 0.05
    field, origin = _sphere_field(40, radius, cell)
    verts, normals, faces = extract_isosurface(field, 0.0, cell, origin)
    assert len(faces) > 1000
    # watertight: every edge is shared by exactly two triangles, with opposite directions (consistent winding)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    directed = {tuple(e) for e in edges.tolist()}
    assert len(directed) == len(edges)
    assert all((b, a) in directed for a, b in directed)
    # outward: vertex normals and triangle windings point away from the centre; enclosed volume is positive
    assert np.all((normals * verts).sum(axis=1) > 0.0)
    a, b, c = (verts[faces[:, i]].astype(np.float64) for i in range(3))
    assert np.all((np.cross(b - a, c - a) * (a + b + c)).sum(axis=1) > 0.0)
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    assert volume == pytest.approx(4.0 / 3.0 * np.pi * radius ** 3, rel=0.02)
    r = np.linalg.norm(verts, axis=1)
    assert abs(r.mean() - radius) < 0.05 * cell and r.std() < 0.1 * cell
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-4)


def test_isosurface_is_closed_where_the_smoke_touches_the_box():
    field = np.full((10, 10, 10), 1.0, np.float32)
    verts, _, faces = extract_isosurface(field, 0.5, 0.1, np.full(3, -0.45))
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)
    assert verts.min() >= -0.5 - 1e-6 and verts.max() <= 0.5 + 1e-6
    assert extract_isosurface(np.zeros((4, 4, 4), np.float32), 0.5, 0.1, np.zeros(3))[2].shape == (0, 3)


def test_ramp_coordinate_stays_in_unit_interval():
    rng = np.random.default_rng(5)
    v = rng.standard_normal((5000, 3)) * rng.uniform(0, 100, (5000, 1))
    g = rng.standard_normal((5000, 3)) * rng.uniform(0, 1e-3, (5000, 1))
    v[:10] = 0.0
    g[10:20] = 0.0
    c = toon_coordinate(v, g)
    assert c.min() >= 0.0 and c.max() <= 1.0
    assert np.all(c[:20] == 0.5)
    d = np.array([[0.0, 0.0, -1.0]])
    assert toon_coordinate(d, d)[0] == 0.0  # looking into the smoke (gradient along the sight): c = 0
    assert toon_coordinate(d, -d)[0] == 1.0
    assert toon_coordinate(d, [[1.0, 0.0, 0.0]])[0] == 0.5  # silhouette


def test_ramp_coordinate_on_a_real_mesh():
    cfg = small()
    state = run_state(cfg, 30, mesh=True)
    assert len(state.mesh_faces) > 100
    eye = np.array([0.0, 0.5, 5.0])
    c = toon_coordinate(state.mesh_vertices - eye, -state.mesh_normals)
    assert c.min() >= 0.0 and c.max() <= 1.0
    assert c.min() < 0.1 and c.max() > 0.9  # both faces towards and away from the eye exist


def test_geometry_round_trip():
    geo = Geometry.build((16, 24, 16), 2, (2.0, 3.0, 2.0))
    p = np.array([[0.3, -1.2, 0.9]])
    assert np.allclose(geo.to_local(geo.to_cells(p)), p)
    assert geo.display_shape == (32, 48, 32)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_marching_cubes_skips_only_cells_without_a_crossing(seed):
    """``surface_cells`` as scikit-image's mask gives exactly the unmasked mesh (vertices, normals, triangles, in
    order) while visiting a fraction of the cells; the field has corners exactly at D_iso and smoke at the walls."""
    from skimage import measure

    from systems.toon_smoke.display import surface_cells

    rng = np.random.default_rng(seed)
    field = upsample_linear(rng.random((6, 7, 5)).astype(np.float32), 4)  # smooth blobs, 24 × 28 × 20
    iso = float(np.quantile(field, 0.6))
    field[rng.random(field.shape) < 0.003] = iso  # some corners exactly at D_iso
    volume = np.pad(field, 1)
    mask = surface_cells(volume, iso)
    assert 0 < mask.sum() < 0.8 * mask.size
    kwargs = dict(level=iso, spacing=(0.1, 0.1, 0.1), gradient_direction="descent", method="lewiner")
    whole = measure.marching_cubes(volume, **kwargs)
    masked = measure.marching_cubes(volume, mask=mask, **kwargs)
    assert len(whole[1]) > 100
    for a, b in zip(whole[:3], masked[:3]):
        assert a.shape == b.shape and a.tobytes() == b.tobytes()
