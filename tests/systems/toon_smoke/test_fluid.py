"""Stable fluids on the MAC grid (seeds/002 §3.1): projection, advection, bounds, obstacles."""

from pathlib import Path

import numpy as np
import pytest

from engine.spatial import Transform
from systems.toon_smoke import fluid, poisson
from systems.toon_smoke.grid import Geometry
from tests.systems.toon_smoke.helpers import preset, run_state, small

N = 24


def _sphere_solid(n: int, radius: float) -> np.ndarray:
    i, j, k = np.indices((n, n, n))
    c = (n - 1) / 2
    return (i - c) ** 2 + (j - c) ** 2 + (k - c) ** 2 < radius ** 2


def _random_velocity(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    f32 = np.float32
    return (rng.standard_normal((n + 1, n, n)).astype(f32), rng.standard_normal((n, n + 1, n)).astype(f32),
            rng.standard_normal((n, n, n + 1)).astype(f32))


@pytest.mark.parametrize("open_sides", [(False, False, False, True, False, False), (False,) * 6])
def test_divergence_after_projection_below_the_stated_bound(open_sides):
    """Bound: max|∇·u| after ≤ tolerance × max|∇·u| before (tolerance 1e-5), with a sphere obstacle, for an open top
    and for a closed box (singular Poisson problem)."""
    solid = _sphere_solid(N, 5.0)
    hierarchy = poisson.build_hierarchy(solid, open_sides)
    u, v, w = _random_velocity(N)
    fluid.enforce_solid_faces(u, v, w, hierarchy)
    phi, before, after, iterations = fluid.project(u, v, w, 0.1, hierarchy, np.zeros((N,) * 3, np.float32), 1e-5, 60)
    assert before > 10.0
    assert after <= 1e-5 * before
    assert iterations < 20  # multigrid-preconditioned CG converges in a handful of iterations
    measured = np.abs(fluid.divergence(u, v, w, 0.1)[~solid]).max()
    assert measured == pytest.approx(after)


def test_projection_leaves_no_flow_into_the_obstacle():
    solid = _sphere_solid(N, 5.0)
    hierarchy = poisson.build_hierarchy(solid, (False, False, False, True, False, False))
    u, v, w = _random_velocity(N, 1)
    fluid.enforce_solid_faces(u, v, w, hierarchy)
    fluid.project(u, v, w, 0.1, hierarchy, np.zeros((N,) * 3, np.float32), 1e-5, 60)
    # every face with a solid cell on either side carries no flow
    touching_x = np.zeros(u.shape, bool)
    touching_x[1:] |= solid
    touching_x[:-1] |= solid
    touching_y = np.zeros(v.shape, bool)
    touching_y[:, 1:] |= solid
    touching_y[:, :-1] |= solid
    assert np.all(u[touching_x] == 0.0) and np.all(v[touching_y] == 0.0)
    # walls (closed sides) carry none either; the open top does
    assert np.all(u[0] == 0.0) and np.all(u[-1] == 0.0) and np.all(v[:, 0] == 0.0)
    assert np.abs(v[:, -1]).max() > 0.0


def test_uniform_velocity_advects_a_blob_by_u_dt():
    """A Gaussian blob in a uniform flow of (0.6, −0.3, 0.2) m/s moves by u·t (centroid within 5 % of a cell)."""
    n, h, dt, steps = 32, 0.1, 0.05, 20
    geo = Geometry.build((n, n, n), 1, (n * h,) * 3)
    vel = np.array([0.6, -0.3, 0.2])
    u = np.full((n + 1, n, n), vel[0], np.float32)
    v = np.full((n, n + 1, n), vel[1], np.float32)
    w = np.full((n, n, n + 1), vel[2], np.float32)
    x, y, z = (c.astype(np.float64) for c in geo.centres)
    start = np.array([12.0, 18.0, 14.0])
    rho = np.exp(-((x - start[0]) ** 2 + (y - start[1]) ** 2 + (z - start[2]) ** 2) / (2 * 2.0 ** 2)).astype(np.float32)
    mass = rho.sum(dtype=np.float64)
    for _ in range(steps):
        (rho,) = fluid.advect_scalars(geo, [rho], u, v, w, dt)
    weights = rho.astype(np.float64)
    centroid = np.array([(weights * np.broadcast_to(c, rho.shape)).sum() / weights.sum() for c in (x, y, z)])
    expected = start + vel * dt * steps / h
    assert np.abs(centroid - expected).max() < 0.05
    assert weights.sum() == pytest.approx(mass, rel=0.02)  # trilinear advection spreads, it does not lose mass here


def test_self_advection_of_uniform_velocity_is_exact():
    n = 16
    geo = Geometry.build((n, n, n), 1, (1.6,) * 3)
    u = np.full((n + 1, n, n), 0.4, np.float32)
    v = np.full((n, n + 1, n), -0.2, np.float32)
    w = np.zeros((n, n, n + 1), np.float32)
    u2, v2, w2 = fluid.advect_velocity(geo, u, v, w, 0.1)
    assert np.allclose(u2, 0.4) and np.allclose(v2, -0.2) and np.allclose(w2, 0.0)


def test_density_stays_non_negative_and_bounded():
    cfg = small(density_limit=2.0)
    state = run_state(cfg, 40, mesh=False)
    for field in (state.density, state.display_density):
        assert field.min() >= 0.0
        assert field.max() <= cfg.density_limit
    assert state.density.max() > 0.5  # the source really emitted
    assert state.temperature.min() >= 0.0 and state.temperature.max() <= cfg.temperature_limit


def test_obstacle_cells_hold_no_smoke_and_no_flux():
    cfg = small()
    state = run_state(cfg, 30)
    assert state.solid.any()
    assert np.all(state.density[state.solid] == 0.0)
    assert np.all(state.display_density[state.display_solid] == 0.0)
    flux = (np.abs(state.u[1:]) + np.abs(state.u[:-1]) + np.abs(state.v[:, 1:]) + np.abs(state.v[:, :-1])
            + np.abs(state.w[:, :, 1:]) + np.abs(state.w[:, :, :-1]))
    assert np.all(flux[state.solid] == 0.0)


def test_paper_setup_divergence_after_each_step():
    """In the paper's setup the measured divergence after projection stays below pressure_tolerance × before."""
    cfg = preset("paper", particle_count=100)
    state = run_state(cfg, 12)
    assert state.divergence_before > 0.5
    assert state.divergence_after <= cfg.pressure_tolerance * state.divergence_before
    assert state.pressure_iterations_used <= cfg.pressure_iterations


def test_implicit_diffusion_conserves_mass_and_smooths():
    rng = np.random.default_rng(3)
    x0 = rng.random((12, 12, 12)).astype(np.float32)
    x = fluid.diffuse(x0, 0.05, 0.1, 0.1, 20)
    assert x.sum(dtype=np.float64) == pytest.approx(x0.sum(dtype=np.float64), rel=1e-4)
    assert x.std() < 0.5 * x0.std()
    assert fluid.diffuse(x0, 0.0, 0.1, 0.1, 20) is x0


def test_buoyant_smoke_rises():
    cfg = small(obstacle_radius=0.0)
    state = run_state(cfg, 40)
    profile = state.density.sum(axis=(0, 2))
    top_half = profile[len(profile) // 2:].sum()
    assert top_half > 0.2 * profile.sum()
    assert state.v.max() > 0.5


def test_expansion_source_pushes_smoke_outwards():
    """A radial source is a divergence source (Feldman et al. 2003): after projection ∇·u ≈ 3·speed/radius inside."""
    cfg = preset("explosion", particle_count=50)
    state = run_state(cfg, 1)
    geo = state.geometry
    div = fluid.divergence(state.u, state.v, state.w, geo.h)
    x, y, z = geo.local_centres()
    src = cfg.sources[0]
    dist2 = (x - src.position[0]) ** 2 + (y - src.position[1]) ** 2 + (z - src.position[2]) ** 2
    inside = dist2 < (0.5 * src.radius) ** 2
    target = 3.0 * src.radial_speed / src.radius
    assert np.median(div[inside]) == pytest.approx(target, rel=0.01)
    assert state.divergence_after <= cfg.pressure_tolerance * state.divergence_before


@pytest.mark.parametrize("shape, scale", [((12, 9, 7), 3.0), ((16, 16, 16), 40.0)])
def test_advection_kernels_match_the_numpy_reference_bit_for_bit(shape, scale):
    """The compiled semi-Lagrangian passes (velocity and scalars) give the numpy reference's bits, on a non-cubic
    grid with random velocities, including back-traces far outside the box (scale 40: clamped)."""
    rng = np.random.default_rng(7)
    nx, ny, nz = shape
    geo = Geometry.build(shape, 1, (nx * 0.1, ny * 0.1, nz * 0.1))
    f32 = np.float32
    u = (scale * rng.standard_normal((nx + 1, ny, nz))).astype(f32)
    v = (scale * rng.standard_normal((nx, ny + 1, nz))).astype(f32)
    w = (scale * rng.standard_normal((nx, ny, nz + 1))).astype(f32)
    u[::3] = 0.0  # back-traces exactly on a sample
    density = rng.random(shape).astype(f32)
    temperature = rng.random(shape).astype(f32)
    smoke = rng.random(shape).astype(f32)
    dt = 0.04
    compiled = fluid.advect_velocity(geo, u, v, w, dt)
    reference = fluid.advect_velocity_numpy(geo, u, v, w, dt)
    for got, want in zip(compiled, reference):
        assert got.dtype == np.float32 and got.shape == want.shape
        assert got.tobytes() == want.tobytes()
    got = fluid.advect_scalars(geo, [density, temperature, smoke], u, v, w, dt)
    want = fluid.advect_scalars_numpy(geo, [density, temperature, smoke], u, v, w, dt)
    assert len(got) == 3
    assert all(g.tobytes() == r.tobytes() for g, r in zip(got, want))
    assert not np.array_equal(got[0], density)  # the flow really moved the field


@pytest.mark.parametrize("open_sides", [(False, False, False, True, False, False), (False,) * 6])
def test_compiled_smoother_matches_the_numpy_reference_bit_for_bit(monkeypatch, open_sides):
    """The compiled red–black smoothing (pre, and prolongation + post), residual and restriction give the numpy reference's bits through a whole MGPCG solve,
    with a sphere obstacle (coarse levels with fractional face coefficients: the weighted stencil) and without."""
    for radius in (5.0, 0.0):
        hierarchy = poisson.build_hierarchy(_sphere_solid(N, radius), open_sides)
        weighted = [level.flat.coefficients is not None for level in hierarchy.levels[:-1]]
        assert any(weighted) == (radius > 0.0)  # both stencil forms are exercised
        u, v, w = _random_velocity(N, seed=3)
        b = -fluid.divergence(u, v, w, 0.1) * np.float32(0.1)
        compiled = poisson.solve_numpy(hierarchy, b, None, 1e-6, 12)
        with monkeypatch.context() as patch:
            _numpy_v_cycle(patch)
            reference = poisson.solve_numpy(hierarchy, b, None, 1e-6, 12)
        assert compiled[1].iterations == reference[1].iterations > 1
        assert compiled[0].tobytes() == reference[0].tobytes()


def _numpy_v_cycle(patch) -> None:
    """Make :func:`poisson.solve_numpy` all numpy: its V-cycle's smoothing, residual and restriction too."""
    patch.setattr(poisson, "_pre_smooth", poisson._pre_smooth_numpy)
    patch.setattr(poisson, "_post_smooth", poisson._post_smooth_numpy)
    patch.setattr(poisson, "_restrict_into", poisson._restrict_numpy)
    patch.setattr(poisson, "_residual", poisson._residual_numpy)


def _sphere_in(shape: tuple[int, int, int], radius: float) -> np.ndarray:
    i, j, k = np.indices(shape)
    c = [(n - 1) / 2 for n in shape]
    return (i - c[0]) ** 2 + (j - c[1]) ** 2 + (k - c[2]) ** 2 < radius ** 2


_CLOSED = (False,) * 6
_OPEN_TOP = (False, False, False, True, False, False)
_EXPLOSION = (True, True, False, True, True, True)  # the explosion preset's open sides


@pytest.mark.parametrize("shape, radius, open_sides, warm, tolerance, max_iterations", [
    ((16, 16, 16), 0.0, _CLOSED, False, 1e-6, 30),  # singular, unweighted levels
    ((16, 16, 16), 4.0, _CLOSED, False, 1e-6, 30),  # singular, an obstacle: weighted coarse levels
    ((16, 16, 16), 4.0, _OPEN_TOP, False, 1e-6, 30),
    ((16, 16, 16), 3.0, _EXPLOSION, True, 1e-4, 30),  # warm start, the demo puff's tolerance
    ((12, 20, 10), 3.0, _EXPLOSION, True, 1e-6, 30),  # non-cubic, a 300-cell dense coarsest level
    ((8, 8, 8), 2.0, _OPEN_TOP, False, 1e-6, 30),  # two levels
    ((4, 4, 4), 0.0, _CLOSED, False, 1e-6, 30),  # one level: the dense solve alone
    ((32, 32, 32), 6.0, _CLOSED, True, 1e-6, 30),  # dot products and means over more than one numpy buffer
    ((16, 16, 16), 4.0, _OPEN_TOP, False, 1e-12, 3),  # stops at max_iterations
])
def test_compiled_solve_matches_the_numpy_solve_bit_for_bit(monkeypatch, shape, radius, open_sides, warm,
                                                            tolerance, max_iterations):
    """The whole MGPCG loop in one compiled call (``poisson.solve``) gives the bits of the numpy reference
    (``poisson.solve_numpy`` with its V-cycle in numpy too): the pressure, the iteration count, the residual and
    max|b|; closed (singular) and open boxes, obstacles, warm starts (x0 nonzero in solid cells too), one to four
    levels, a run that hits max_iterations; then again from its own solution (0 or 1 more iterations), and b = 0
    (the early return)."""
    hierarchy = poisson.build_hierarchy(_sphere_in(shape, radius), open_sides)
    assert hierarchy.singular == (open_sides == _CLOSED)
    assert hierarchy.levels[0].active.all() == (radius == 0.0)
    if radius >= 4.0:  # smoothed coarse levels with fractional face coefficients: the weighted stencil
        assert any(level.flat.coefficients is not None for level in hierarchy.levels[:-1])
    rng = np.random.default_rng(11)
    b = rng.standard_normal(shape).astype(np.float32)
    x0 = (0.3 * rng.standard_normal(shape)).astype(np.float32) if warm else None
    with monkeypatch.context() as patch:
        _numpy_v_cycle(patch)
        reference = [poisson.solve_numpy(hierarchy, b, x0, tolerance, max_iterations)]
        reference.append(poisson.solve_numpy(hierarchy, b, reference[0][0], tolerance, max_iterations))
        reference.append(poisson.solve_numpy(hierarchy, np.zeros_like(b), x0, tolerance, max_iterations))
    compiled = [poisson.solve(hierarchy, b, x0, tolerance, max_iterations)]
    compiled.append(poisson.solve(hierarchy, b, compiled[0][0], tolerance, max_iterations))
    compiled.append(poisson.solve(hierarchy, np.zeros_like(b), x0, tolerance, max_iterations))
    first = reference[0][1]
    assert first.iterations == max_iterations if max_iterations < 30 else 0 < first.iterations < max_iterations
    assert reference[2][1].iterations == 0
    for (x, report), (want_x, want_report) in zip(compiled, reference):
        assert x.dtype == want_x.dtype == np.float32 and x.shape == want_x.shape == shape
        assert np.array_equal(x.view(np.uint32), want_x.view(np.uint32))  # every bit, the sign of zero too
        assert report.iterations == want_report.iterations
        assert report.residual == want_report.residual and report.rhs == want_report.rhs


def test_pairwise_sum_is_numpys_sum_bit_for_bit():
    """The compiled solve's float64 sums are numpy's: a contiguous run summed pairwise (every length from 1 to
    5000, a few longer, from an offset too), and a float32 field's float64 sum over its active cells (cast and
    summed one numpy buffer at a time) with the zero-mean projection that uses it.  The values span 22 decades,
    so that another order of the additions rounds differently (a plain left-to-right sum differs for 9 lengths in
    10); the solve's own test would miss most such slips, as its dot products are rounded to float32 before use."""
    from engine.jit import pairwise_sum
    from systems.toon_smoke.kernels import _remove_mean, _sum_active

    rng = np.random.default_rng(5)

    def spread(n):
        return np.exp(rng.uniform(-25.0, 25.0, n)) * rng.choice([-1.0, 1.0], n)

    for n in list(range(1, 5001)) + [8191, 8192, 8193, 65536, 100003]:
        values = spread(n)
        assert 0.0 + pairwise_sum(values, 0, n) == float(values.sum())
        assert pairwise_sum(values, 1, n - 1) + 0.0 == float(values[1:].sum())
    buffer = np.getbufsize()
    for n, buffer_size in [(100, buffer), (8193, buffer), (40000, buffer), (40000, 1024)]:
        field = spread(n).astype(np.float32)
        active = rng.random(n) < 0.9
        want = field.copy()
        try:
            np.setbufsize(buffer_size)
            want_sum = float(field[active].sum(dtype=np.float64))
            poisson._remove_mean(want, active)
        finally:
            np.setbufsize(buffer)
        assert _sum_active(field, active, np.empty(n), buffer_size) == (want_sum, active.sum())
        got = field.copy()
        _remove_mean(got, active, np.empty(n), buffer_size)
        assert np.array_equal(got.view(np.uint32), want.view(np.uint32))


@pytest.mark.parametrize("shape", [(16, 16, 16), (12, 20, 9)])
def test_particle_kernels_match_the_mac_sampler_bit_for_bit(shape):
    """The compiled midpoint rule and velocity query (``advect_particles``) against the numpy MAC sampler, at
    points inside and outside the box (clamped), with the float64 positions and float32 velocities of the state."""
    from systems.toon_smoke.grid import MacSampler
    from systems.toon_smoke.kernels import advect_particles_kernel, mac_velocity_kernel

    geo = Geometry.build(shape, 2, (3.0, 4.0, 2.5))
    rng = np.random.default_rng(4)
    nx, ny, nz = shape
    f32 = np.float32
    u, v, w = (rng.standard_normal(s).astype(f32) for s in ((nx + 1, ny, nz), (nx, ny + 1, nz), (nx, ny, nz + 1)))
    p = rng.uniform(-1.0, 1.0, (500, 3)) * 0.6 * geo.extent  # a fifth of them outside the box
    dt = 1.0 / 60.0
    sampler = MacSampler(u, v, w)

    def reference(points):
        return np.stack(sampler.sample(geo.to_cells(points).T), axis=-1)

    half = 0.5 * geo.extent
    np.testing.assert_array_equal(mac_velocity_kernel(p, u, v, w, half, float(geo.h)).view(np.int64),
                                  reference(p).view(np.int64))
    mid = p + 0.5 * dt * reference(p)
    velocity = reference(mid)
    moved, got_velocity = advect_particles_kernel(p, u, v, w, half, float(geo.h), 0.5 * dt, dt)
    np.testing.assert_array_equal(got_velocity.view(np.int64), velocity.view(np.int64))
    np.testing.assert_array_equal(moved.view(np.int64), (p + dt * velocity).view(np.int64))


@pytest.mark.parametrize("confinement", [0.0, 0.35])
@pytest.mark.parametrize("up", [(0.0, 1.0, 0.0), (0.3, 0.9, -0.2)])
def test_body_forces_kernel_matches_the_numpy_reference_bit_for_bit(confinement, up):
    """Buoyancy along a vertical or tilted up and vorticity confinement, compiled (one pass) against the numpy
    code (cell forces, then face averages), on a non-cubic grid."""
    n = (12, 9, 7)
    rng = np.random.default_rng(6)
    f32 = np.float32
    u, v, w = (rng.standard_normal(s).astype(f32) for s in ((n[0] + 1, n[1], n[2]), (n[0], n[1] + 1, n[2]),
                                                           (n[0], n[1], n[2] + 1)))
    temperature, density = rng.random(n).astype(f32), rng.random(n).astype(f32)
    up = np.array(up) / np.linalg.norm(up)
    got = [c.copy() for c in (u, v, w)]
    want = [c.copy() for c in (u, v, w)]
    fluid.body_forces(*got, temperature, density, 1.7, 0.4, up, confinement, 0.125, 1.0 / 60.0)
    fluid.body_forces_numpy(*want, temperature, density, 1.7, 0.4, up, confinement, 0.125, 1.0 / 60.0)
    for axis, (a, b, before) in enumerate(zip(got, want, (u, v, w))):
        assert a.tobytes() == b.tobytes()
        assert np.array_equal(a, before) == (up[axis] == 0.0 and confinement == 0.0)  # forced where it should be


def test_a_volume_moving_with_no_collider_in_reach_keeps_its_solver_hierarchy():
    """The sphere obstacle lives in the volume's frame: moving the volume alone changes no solid cell, so the
    masks and the multigrid are not rebuilt (they were, every tick: 18 ms a tick on the paper preset)."""
    from engine.spatial import Transform
    from systems.toon_smoke import simulate

    cfg = small()
    state = simulate.new_state(cfg, np.random.default_rng(0))
    transform = Transform()
    simulate.update_obstacles(None, 1, transform, cfg, state)
    hierarchy, solid = state.hierarchy, state.solid.copy()
    transform.position = transform.position + np.array([3.0, 1.0, -2.0])
    simulate.update_obstacles(None, 1, transform, cfg, state)
    assert state.hierarchy is hierarchy and np.array_equal(state.solid, solid) and solid.any()


def _bits(a: np.ndarray) -> bytes:
    """Every bit of an array (the sign of zero and NaN payloads too)."""
    return np.ascontiguousarray(a).view(np.uint8).tobytes()


def _same_float(a: float, b: float) -> bool:
    return np.float64(a).tobytes() == np.float64(b).tobytes()


def _face_velocities(shape, rng, scale=1.0):
    nx, ny, nz = shape
    return [(scale * rng.standard_normal(s)).astype(np.float32)
            for s in ((nx + 1, ny, nz), (nx, ny + 1, nz), (nx, ny, nz + 1))]


@pytest.mark.parametrize("shape, radius, open_sides, target, warm, poison", [
    ((16, 16, 16), 3.0, _EXPLOSION, True, True, None),  # the demo puff: an obstacle, a blast's target divergence
    ((16, 16, 16), 3.0, _EXPLOSION, False, True, None),  # the same puff once the blast is over
    ((16, 16, 16), 4.0, _CLOSED, False, False, None),  # closed box (singular), cold start
    ((12, 20, 10), 0.0, _OPEN_TOP, True, False, None),  # empty grid (no solid cell), non-cubic
    ((8, 8, 8), 99.0, _EXPLOSION, True, True, None),  # full grid: every cell solid, nothing to solve
    ((16, 16, 16), 3.0, _EXPLOSION, True, False, "nan"),  # a NaN face velocity: max|∇·u| is NaN, as in numpy
    ((16, 16, 16), 3.0, _OPEN_TOP, False, False, "zero"),  # still air: zero divergence, signed zeros in u
])
def test_compiled_projection_matches_the_numpy_projection_bit_for_bit(shape, radius, open_sides, target, warm,
                                                                      poison):
    """``fluid.project`` (the divergence, right-hand side, gradient update and divergence after in two compiled
    calls around the solve) gives the bits of ``fluid.project_numpy`` (whole-array expressions): the updated
    faces, φ, the divergence before and after and the iteration count.  The velocities span six decades, so a
    sum taken in another order or a product with another rounding changes bits."""
    rng = np.random.default_rng(21)
    hierarchy = poisson.build_hierarchy(_sphere_in(shape, radius), open_sides)
    assert hierarchy.levels[0].active.any() == (radius < 99.0)
    velocity = [c * np.exp(rng.uniform(-7.0, 7.0, c.shape)).astype(np.float32) for c in _face_velocities(shape, rng)]
    fluid.enforce_solid_faces(*velocity, hierarchy)
    if poison == "nan":
        velocity[0][8, 8, 1] = np.nan  # a fluid cell's face (the sphere of radius 3 is centred)
    elif poison == "zero":
        for c in velocity:
            c[...] = 0.0
        velocity[1][::2] = -0.0
    divergence = (rng.standard_normal(shape) * (rng.random(shape) < 0.2)).astype(np.float32) if target else None
    pressure = (0.1 * rng.standard_normal(shape)).astype(np.float32) if warm else np.zeros(shape, np.float32)
    got = [c.copy() for c in velocity]
    want = [c.copy() for c in velocity]
    phi, before, after, iterations = fluid.project(*got, 0.3, hierarchy, pressure, 1e-4, 30, divergence)
    want_phi, want_before, want_after, want_iterations = fluid.project_numpy(*want, 0.3, hierarchy, pressure,
                                                                             1e-4, 30, divergence)
    for a, b in zip(got, want):
        assert _bits(a) == _bits(b)
    assert _bits(phi) == _bits(want_phi)
    assert _same_float(before, want_before) and _same_float(after, want_after)
    assert isinstance(before, float) and isinstance(after, float)
    assert iterations == want_iterations
    if poison is None and radius < 99.0:  # a real solve ran and changed the flow
        assert iterations > 0 and before > 1.0 and not all(np.array_equal(a, b) for a, b in zip(got, velocity))
    assert np.isnan(before) == (poison == "nan")


@pytest.mark.parametrize("hierarchy, dissipation, cooling", [(True, 0.35, 1.2), (True, 0.0, 0.0), (False, 0.5, 0.0)])
def test_compiled_fade_and_clamp_matches_the_numpy_reference_bit_for_bit(hierarchy, dissipation, cooling):
    """The scalars' fade, solid clearing and clamp (``simulate.fade_and_clamp``) against the numpy code: values above
    the limits, NaN, signed zeros, solids (a hierarchy) or none, each fade on or off."""
    from systems.toon_smoke import simulate

    cfg = small(density_dissipation=dissipation, temperature_cooling=cooling, density_limit=2.0,
                temperature_limit=3.0)
    state = simulate.new_state(cfg, np.random.default_rng(0))
    if hierarchy:
        simulate.update_obstacles(None, 1, Transform(), cfg, state)
        assert state.solid.any()
    rng = np.random.default_rng(8)
    shape = state.density.shape
    fields = [(4.0 * rng.standard_normal(shape)).astype(np.float32) for _ in range(2)]
    for f in fields:
        f[0, 0, :4] = (np.nan, -0.0, 0.0, np.inf)
        f[1, 1, 1] = 2.0  # exactly the density limit
    want = simulate.fade_and_clamp_numpy(cfg, state, *[f.copy() for f in fields], 1.0 / 60.0)
    got = simulate.fade_and_clamp(cfg, state, *[f.copy() for f in fields], 1.0 / 60.0)
    for g, w, f, limit in zip(got, want, fields, (2.0, 3.0)):
        assert g.dtype == np.float32 and _bits(g) == _bits(w)
        assert np.nanmax(g) == limit and np.isnan(g[0, 0, 0])
    assert (np.array_equal(got[0], np.minimum(fields[0], np.float32(2.0)), equal_nan=True)
            == (not hierarchy and dissipation == 0.0))


def test_compiled_clamp_breaks_ties_as_numpy():
    """``np.minimum`` returns its second operand (the limit) on a tie: with a limit of +0 a −0 becomes +0, with −0
    a +0 becomes −0; the kernel does the same."""
    from systems.toon_smoke.kernels import fade_and_clamp_kernel

    for limit in (np.float32(0.0), np.float32(-0.0)):
        values = np.array([-0.0, 0.0, -1.0, 1.0, np.nan], np.float32).reshape(1, 1, 5)
        got = values.copy()
        fade_and_clamp_kernel(got, got.copy(), False, np.float32(1.0), False, np.float32(1.0), got, False, limit,
                              limit)
        assert _bits(got) == _bits(np.minimum(values, limit))


@pytest.mark.parametrize("lifetime, solid", [(0.0, "sphere"), (0.4, "sphere"), (0.4, "random"), (0.4, None),
                                             (0.0, "none")])
def test_compiled_rebirth_matches_the_numpy_reference(lifetime, solid):
    """Which particles are reborn (``simulate.rebirth``) and their ages, against the numpy code: particles inside,
    outside, exactly on the box's faces, in and next to solid display cells, with a NaN coordinate (cell 0), ages
    reaching the lifetime exactly; with and without a lifetime, with the obstacle's display solid, a random one,
    none, or one with no solid cell."""
    from systems.toon_smoke import simulate

    cfg = small(particle_lifetime=lifetime)
    state = simulate.new_state(cfg, np.random.default_rng(0))
    simulate.update_obstacles(None, 1, Transform(), cfg, state)
    rng = np.random.default_rng(9)
    if solid is None:
        state.display_solid = None
    elif solid == "none":
        state.display_solid = np.zeros_like(state.display_solid)
    elif solid == "random":
        state.display_solid = rng.random(state.display_solid.shape) < 0.5
        state.display_solid[0] = True  # where a NaN coordinate looks (numpy's cast gives cell 0)
        state.display_solid[-1] = False
    half = 0.5 * state.geometry.extent
    p = rng.uniform(-1.1, 1.1, (4000, 3)) * half
    p[:30] = rng.uniform(-0.35, 0.35, (30, 3))  # about the sphere obstacle's surface (radius 0.3)
    p[30:36] = [half, -half, [half[0], 0.0, 0.0], [-half[0], 0.0, 0.0], [0.0, np.nextafter(half[1], 9.0), 0.0],
                [np.nan, 0.0, 0.0]]
    dt = 1.0 / 60.0
    ages = rng.uniform(0.0, 0.5, len(p))
    exact = 0.4 - dt  # ages that reach the lifetime exactly after this step, and the float either side
    while exact + dt != 0.4:
        exact = np.nextafter(exact, 1.0)
    ages[36:39] = [np.nextafter(exact, 0.0), exact, np.nextafter(exact, 1.0)]
    ages[35] = 0.0  # the NaN particle: reborn only for its cell
    p[36:39] = 0.5 * half  # inside, clear of the obstacle
    state.particle_age = ages.copy()
    with np.errstate(invalid="ignore"):  # numpy's cast of the NaN coordinate to a cell index
        want, want_count = simulate.rebirth_numpy(cfg, state, p, dt)
    want_ages = state.particle_age
    state.particle_age = ages.copy()
    got, count = simulate.rebirth(cfg, state, p, dt)
    assert np.array_equal(got, want) and count == want_count == int(want.sum())
    assert _bits(state.particle_age) == _bits(want_ages)
    inside = ~np.any(np.abs(p) > half, axis=1)
    assert 0 < count and not want[inside].all() and want[~inside & ~np.isnan(p).any(axis=1)].all()
    if solid == "sphere":
        assert want[:30].any() and not want[:30].all()  # some near the obstacle are in it, some not
    if lifetime > 0.0 and solid != "random":
        assert list(want[36:39]) == [False, True, True]
    assert want[35] == (solid == "random")  # the NaN particle


def test_collider_bounds_test_matches_the_numpy_reference():
    """The per-step bounding test of other colliders (``simulate._overlapping_colliders``, Python floats) keeps
    exactly the colliders of its numpy reference, with spheres and boxes placed right at the boundary (the gap
    equal to the reach, and one float either side), scaled, height fields whose highest point is just below, at
    or above the volume's lowest reach (flat, or a lone peak far from the volume), one with a NaN height, and
    triggers."""
    from engine.collider import Collider
    from engine.exact import length
    from engine.heightfield import HeightField
    from engine.world import World
    from systems.toon_smoke import simulate

    cfg = small()
    world = World()
    rng = np.random.default_rng(12)
    volume = Transform(position=np.array([0.3, 1.7, -2.2]))
    reach = 0.5 * float(length(np.asarray(cfg.extent, float)))
    for n in range(300):
        direction = rng.standard_normal(3)
        position = volume.position + direction / np.linalg.norm(direction) * rng.uniform(reach + 0.1, reach + 3.0)
        scale = rng.uniform(0.5, 2.0, 3) if n % 3 else np.ones(3)
        gap = float(length(position - volume.position)) - reach
        if n % 2:  # a sphere whose scaled radius is the gap, or the float just below or above it
            size = float(np.nextafter(gap, [-9.0, gap, 9.0][n % 3])) / float(np.max(np.abs(scale)))
            collider = Collider(shape="sphere", radius=size)
        else:  # a box whose scaled half-diagonal is near the gap
            e = abs(gap) * rng.dirichlet(np.ones(3)) ** 0.5
            collider = Collider(shape="box", half_extents=e / scale)
        world.spawn(Transform(position=position, scale=scale), collider)
    bottom = volume.position[1] - reach
    for top in (-1.0, 0.0, 1.0):  # the volume's lowest reach against the field's highest point: flat fields,
        heights = np.full((4, 4), bottom + top)  # then rough ones whose peak is far from the volume
        world.spawn(Transform(position=np.array([0.0, 0.0, 0.0])), Collider(shape="heightfield",
                                                                           heightfield=HeightField(heights)))
        heights = bottom - rng.uniform(0.5, 2.0, (9, 7))
        heights[8, 6] = bottom + top
        world.spawn(Transform(position=np.array([0.0, 0.0, 0.0])), Collider(shape="heightfield",
                                                                           heightfield=HeightField(heights)))
    heights = bottom - rng.uniform(0.5, 2.0, (9, 7))
    heights[0, 3] = np.nan
    world.spawn(Transform(), Collider(shape="heightfield", heightfield=HeightField(heights)))
    world.spawn(Transform(position=volume.position.copy()), Collider(shape="sphere", is_trigger=True))
    own = world.spawn(Transform(position=volume.position.copy()), Collider(shape="sphere"))
    got = simulate._overlapping_colliders(world, own, volume, cfg)
    want = simulate._overlapping_colliders_numpy(world, own, volume, cfg)
    assert [e for e, _, _ in got] == [e for e, _, _ in want]
    assert 50 < len(got) < 250  # both sides of the boundary
    assert [e - 300 for e, _, c in got if c.shape == "heightfield"] == [3, 4, 5, 6, 7]  # the top at or above the
    # bottom, or a NaN height


@pytest.mark.parametrize("volume_turn, field_turn", [(0.0, 0.0), (0.7, 0.0), (0.0, -1.1), (2.3, 0.4)])
def test_compiled_height_field_mask_matches_the_colliders_own_test(volume_turn, field_turn):
    """The solid cells under height field colliders (``simulate._solid_mask``, compiled) are those of the colliders'
    own ``signed_distance`` (``_solid_mask_numpy``), on the simulation and the display grid: a rough field crossing
    the volume, unrotated or turned about tilted axes, a second field the volume reaches past its border (clamped
    samples), a box collider beside them, the sphere obstacle."""
    from engine.collider import Collider
    from engine.heightfield import HeightField
    from engine.spatial import quat_from_axis_angle
    from systems.toon_smoke import simulate

    cfg = small(obstacle_radius=0.4)
    geo = simulate.geometry_for(cfg)
    rng = np.random.default_rng(14)
    volume = Transform(position=np.array([3.1, 0.45, -2.7]), rotation=quat_from_axis_angle([0.3, 1.0, 0.2],
                                                                                           volume_turn))
    rough = HeightField(rng.uniform(-0.6, 0.6, (23, 31)), spacing=0.17, origin=np.array([1.2, -4.6]))
    edge = HeightField(rng.uniform(-0.3, 0.9, (5, 4)), spacing=0.35, origin=np.array([3.4, -3.1]))
    colliders = [
        (1, Transform(position=np.array([0.05, 0.3, 0.1]), rotation=quat_from_axis_angle([0.1, 1.0, -0.4],
                                                                                            field_turn)),
         Collider(shape="heightfield", heightfield=rough)),
        (2, Transform(position=np.array([0.0, -0.2, 0.0])), Collider(shape="heightfield", heightfield=edge)),
        (3, Transform(position=np.array([3.6, 0.9, -2.4])), Collider(shape="box", half_extents=[0.3, 0.2, 0.4])),
    ]
    for centres in (geo.local_centres(), geo.local_display_centres()):
        got = simulate._solid_mask(centres, volume, cfg, colliders)
        want = simulate._solid_mask_numpy(centres, volume, cfg, colliders)
        assert got.dtype == bool and np.array_equal(got, want)
        assert 0.1 < got.mean() < 0.9  # the surface really crosses the volume
        for k in (0, 1):  # each height field alone, so neither hides the other's cells
            assert np.array_equal(simulate._solid_mask(centres, volume, cfg, colliders[k:k + 1]),
                                  simulate._solid_mask_numpy(centres, volume, cfg, colliders[k:k + 1]))


def test_compiled_height_field_mask_keeps_cells_exactly_on_the_surface_out():
    """A flat field through a row of display cell centres exactly (d = 0: not solid, as ``signed_distance < 0``
    says), at rows whose coordinates round differently when summed in another order: a slip in the compiled
    path's order would move those cells in or out."""
    from engine.collider import Collider
    from engine.heightfield import HeightField
    from systems.toon_smoke import simulate

    cfg = small(obstacle_radius=0.0)
    geo = simulate.geometry_for(cfg)
    volume = Transform(position=np.array([0.37, 0.7316294, -0.61]))
    placed = Transform(position=np.array([0.1, -0.2938471, 0.0]))
    centres = geo.local_display_centres()
    ys = centres[1].reshape(-1)
    rows = [r for r in range(1, len(ys) - 1)  # where the sums associated the other way round differently
            if (volume.position[1] + ys[r]) - placed.position[1] != volume.position[1] + (ys[r] - placed.position[1])]
    assert len(rows) >= 3
    for row in rows[:3]:
        level = (volume.position[1] + ys[row]) - placed.position[1]  # the row's height in the field's frame
        field = HeightField(np.full((3, 3), level), spacing=4.0, origin=np.array([-4.0, -4.0]))
        colliders = [(1, placed, Collider(shape="heightfield", heightfield=field))]
        got = simulate._solid_mask(centres, volume, cfg, colliders)
        assert np.array_equal(got, simulate._solid_mask_numpy(centres, volume, cfg, colliders))
        assert not got[:, row].any() and got[:, :row].all() and not got[:, row + 1:].any()


_COARSE_INVERSE = """
import hashlib, sys
import numpy as np
from systems.toon_smoke.poisson import build_hierarchy
solid = np.zeros((16, 16, 16), bool)
solid[:, :3, :] = True
solid[5:8, 5:9, 4:7] = True
for sides in [(True,) * 6, (False,) * 6, (False, False, False, True, False, False)]:
    sys.stdout.write(hashlib.sha256(build_hierarchy(solid, sides).levels[-1].dense_inverse.tobytes()).hexdigest())
"""


def test_coarsest_inverse_has_the_same_bits_with_every_blas_kernel():
    """LAPACK's SVD (np.linalg.pinv) gave other last bits with OpenBLAS's kernels for other CPUs; the coarsest
    level's pseudo-inverse is computed without BLAS, so a puff's solve is the same on every machine."""
    import os
    import subprocess
    import sys

    digests = set()
    for core in ("Prescott", "Sandybridge", "Haswell"):
        env = dict(os.environ, OPENBLAS_CORETYPE=core)
        digests.add(subprocess.run([sys.executable, "-c", _COARSE_INVERSE], env=env, capture_output=True, text=True,
                                   check=True, cwd=Path(__file__).resolve().parents[3]).stdout)
    assert len(digests) == 1


@pytest.mark.parametrize("open_sides", [(True,) * 6, (False,) * 6, (False, False, False, True, False, False)])
@pytest.mark.parametrize("split", [False, True])
def test_coarsest_inverse_is_the_pseudo_inverse(open_sides, split):
    """(M + U Uᵀ)⁻¹ − U Uᵀ with U the constants of each closed group of cells: the Moore–Penrose inverse, also when
    a wall splits the box into two groups without an open face."""
    from systems.toon_smoke.poisson import _dense_operator, build_hierarchy

    solid = np.zeros((16, 16, 16), bool)
    solid[:, :3, :] = True
    if split:
        solid[4:8, :, :] = True  # one whole coarsest cell thick: two groups there too
    level = build_hierarchy(solid, open_sides).levels[-1]
    m, inverse = _dense_operator(level), level.dense_inverse
    if split:
        assert not level.active.reshape(level.shape)[1].any() and level.active.sum() > 32
    reference = np.linalg.pinv(m)
    assert np.abs(inverse - reference).max() <= 1e-12 * np.abs(reference).max()
    assert np.abs(m @ inverse @ m - m).max() <= 1e-12 * np.abs(m).max()


def test_a_height_field_beside_the_volume_makes_no_cell_solid():
    """A height field is solid only over its footprint. Every cell below a pond's level was solid, however far
    beside it (the clamped height extends its border outwards): a volume at x = -10, y = 0 with a pond 20 m away at
    y = 5 had all 512 of 512 cells solid. Now none are; a volume straddling the pond's edge is solid only over the
    footprint, in the compiled mask and its numpy reference alike."""
    from engine.collider import Collider
    from engine.heightfield import HeightField
    from engine.world import World
    from systems.toon_smoke import simulate

    cfg = small(obstacle_radius=0.0, simulation_resolution=[8, 8, 8], display_resolution=[16, 16, 16],
                extent=[2.0, 2.0, 2.0])
    pond = HeightField(np.zeros((16, 16)), spacing=0.5, origin=np.array([-3.75, -3.75]))
    world = World()
    world.spawn(Transform(position=np.array([10.0, 5.0, 0.0])), Collider(shape="heightfield", heightfield=pond,
                                                                        layer="water"))
    volume = world.spawn(Transform(position=np.array([-10.0, 0.0, 0.0])))
    state = simulate.new_state(cfg, np.random.default_rng(0))
    transform = world.get(volume, Transform)
    assert len(simulate._overlapping_colliders(world, volume, transform, cfg)) == 1  # it is in reach (by height)
    simulate.update_obstacles(world, volume, transform, cfg, state)
    assert state.solid.size == 512 and not state.solid.any() and not state.display_solid.any()

    edge = Transform(position=np.array([10.0 - 3.75, 4.0, 0.0]))  # centred on the pond's x = -3.75 wall, below
    geo = simulate.geometry_for(cfg)
    colliders = simulate._overlapping_colliders(world, volume, edge, cfg)
    for centres in (geo.local_centres(), geo.local_display_centres()):
        got = simulate._solid_mask(centres, edge, cfg, colliders)
        assert np.array_equal(got, simulate._solid_mask_numpy(centres, edge, cfg, colliders))
        x = np.broadcast_arrays(*centres)[0]
        assert np.array_equal(got, x >= 0.0)  # the half over the footprint (all of it below the surface)
