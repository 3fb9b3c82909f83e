"""Wave propagation (eq. 2.8–2.10): speed c, reflecting borders, damping, conserved volume, the stability limit."""

from __future__ import annotations

import numpy as np
import pytest

from engine import exact
from components.water_surface import STABILITY_LIMIT
from systems.water_surface.surface import step_water
from systems.water_surface.waves import courant_k, free_degree, neighbour_sum, propagate
from tests.systems.water_surface.helpers import make_grid, make_state, water_config

DT = 1.0 / 60.0


def _gaussian(n: int, h: float, centre: tuple[float, float], sigma: float, height: float = 0.1) -> np.ndarray:
    x = np.arange(n) * h
    gx, gz = np.meshgrid(x, x)
    return height * np.exp(-((gx - centre[0]) ** 2 + (gz - centre[1]) ** 2) / (2 * sigma ** 2))


def _energy(z1: np.ndarray, z0: np.ndarray, k: float, degree: np.ndarray) -> float:
    """The discrete energy leapfrog conserves: |z1 − z0|² + k·<z1, L z0>, L = D − W the graph Laplacian."""
    lap = degree * z0 - neighbour_sum(z0)
    return float(np.sum((z1 - z0) ** 2) + k * np.sum(z1 * lap))


def test_neighbour_counts_make_the_borders_reflect():
    d = free_degree(5, 6)
    assert d[2, 3] == 4 and d[0, 3] == 3 and d[2, 0] == 3 and d[0, 0] == 2 and d[4, 5] == 2  # eq. 2.8–2.10


def test_a_disturbance_travels_at_c():
    n, h, c = 161, 0.05, 1.0
    k = courant_k(c, h, DT)
    centre = (n - 1) * h / 2
    z = _gaussian(n, h, (centre, centre), sigma=0.15)
    zp = z.copy()
    degree = free_degree(n, n)
    row = n // 2
    radii = (1.5, 3.0)
    cols = [row + int(round(r / h)) for r in radii]
    history = []
    for _ in range(240):  # 4 s: the ring reaches 3 m at 3 s, the border echo (4 m + 1 m) not before 5 s
        z, zp = propagate(z, zp, k, 2.0 - k * degree, degree)[0], z
        history.append(z[row, cols])
    history = np.array(history)
    peak = np.argmax(history, axis=0) + 1  # steps at which the ring's crest passes each radius
    speed = (radii[1] - radii[0]) / ((peak[1] - peak[0]) * DT)
    assert speed == pytest.approx(c, rel=0.05)
    arrival = np.argmax(history[:, 1] > 0.05 * history[:, 1].max()) + 1
    assert arrival * DT == pytest.approx(radii[1] / c - 2 * 0.15 / c, abs=0.25)  # the front leads the crest


def test_a_pulse_reflects_at_the_border_without_changing_sign():
    nx, nz, h, c = 201, 3, 0.05, 1.0
    k = courant_k(c, h, DT)
    x = np.arange(nx) * h
    x0, sigma = 5.0, 0.25
    z = np.tile(np.exp(-((x - x0) ** 2) / (2 * sigma ** 2)), (nz, 1))  # moving towards +x (the wall at 10 m)
    zp = np.tile(np.exp(-((x - x0 + c * DT) ** 2) / (2 * sigma ** 2)), (nz, 1))
    degree = free_degree(nz, nx)
    centroids = []
    for _ in range(630):
        z, zp = propagate(z, zp, k, 2.0 - k * degree, degree)[0], z
        w = np.clip(z[1], 0.0, None)
        centroids.append(float(np.sum(w * x) / np.sum(w)))
    assert max(centroids) > 9.7  # it reached the wall ...
    back = centroids[599]  # ... and after 2·(10 − 5)/c = 10 s it is back where it started
    assert back == pytest.approx(x0, abs=0.15)
    assert centroids[629] < back - 0.3  # still moving away from the wall
    assert z[1].max() > 0.9 and z[1].min() > -0.1  # reflected upright (a free end), barely dispersed


def test_without_damping_the_discrete_energy_is_conserved():
    grid = make_grid(40, 0.1)
    cfg = water_config(resolution=[40, 40], spacing=0.1, wave_speed=2.0, damping=1.0)
    state = make_state(grid)
    state.heights[:] = _gaussian(40, 0.1, (1.5, 2.2), sigma=0.2)
    state.previous[:] = state.heights
    k = courant_k(2.0, 0.1, DT)
    degree = free_degree(40, 40)
    from systems.water_surface.geometry import empty_bodies

    energies = []
    for _ in range(300):
        step_water(state, cfg, grid, empty_bodies(), DT)
        energies.append(_energy(state.heights, state.previous, k, degree))
    assert np.ptp(energies) < 1e-9 * energies[0]


def test_damping_below_one_makes_the_energy_decay_and_keeps_the_mean():
    grid = make_grid(40, 0.1)
    cfg = water_config(resolution=[40, 40], spacing=0.1, wave_speed=2.0, damping=0.99)
    state = make_state(grid)
    state.heights[:] = _gaussian(40, 0.1, (1.5, 2.2), sigma=0.2)  # a mound: its mean is not zero
    state.previous[:] = state.heights
    mean0 = state.heights.mean()
    k = courant_k(2.0, 0.1, DT)
    degree = free_degree(40, 40)
    from systems.water_surface.geometry import empty_bodies

    energies = []
    for _ in range(300):
        step_water(state, cfg, grid, empty_bodies(), DT)
        energies.append(_energy(state.heights - mean0, state.previous - mean0, k, degree))
    # z(t+1) = d·(2 z − z(t−1) − k·L z): the amplitude shrinks by √d per step, the energy by d
    assert energies[-1] / energies[0] == pytest.approx(0.99 ** 300, rel=0.3)
    assert all(b < a for a, b in zip(energies[::30], energies[30::30]))
    assert state.heights.mean() == pytest.approx(mean0, abs=1e-12)  # no water leaks away


def test_the_update_alone_conserves_the_mean():
    rng = np.random.default_rng(2)
    z = rng.normal(size=(30, 20))
    zp = z + 0.01 * rng.normal(size=(30, 20))
    zp += z.mean() - zp.mean()
    degree = free_degree(30, 20)
    for _ in range(100):
        z, zp = propagate(z, zp, 0.4, 2.0 - 0.4 * degree, degree)[0], z
    assert z.mean() == pytest.approx(zp.mean(), abs=1e-12)


@pytest.mark.parametrize("courant, stable", [(0.70, True), (STABILITY_LIMIT, True), (0.75, False)])
def test_the_2d_stability_limit_is_where_the_scheme_blows_up(courant, stable):
    rng = np.random.default_rng(0)
    z = rng.normal(size=(24, 24)) * 1e-3
    zp = z.copy()
    degree = free_degree(24, 24)
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(1500):
            z, zp = propagate(z, zp, courant ** 2, 2.0 - courant ** 2 * degree, degree)[0], z
    grew = np.abs(z).max() / 1e-3
    assert (grew < 10.0) if stable else not (grew < 1e3)  # NaN after an overflow counts as blown up


def _dents_unclipped(grid, centres_uv, heights, radius):
    """dents as it was: each drop's whole 2·reach square listed, then the vertices off the grid dropped."""
    from systems.water_surface.geometry import ranges

    r = radius / grid.h
    reach = int(np.ceil(2.0 * r))
    lo = np.floor(centres_uv).astype(np.int64) - reach + 1
    side = 2 * reach
    drop, offset = ranges(np.zeros(len(centres_uv), np.int64), np.full(len(centres_uv), side * side))
    dv, du = np.divmod(offset, side)
    i, j = lo[drop, 0] + du, lo[drop, 1] + dv
    ok = (i >= 0) & (i < grid.nx) & (j >= 0) & (j < grid.nz)
    drop, i, j = drop[ok], i[ok], j[ok]
    change = -heights[drop] * exact.exp(-((i - centres_uv[drop, 0]) ** 2 + (j - centres_uv[drop, 1]) ** 2) / (r * r))
    touched, inverse = np.unique(j * grid.nx + i, return_inverse=True)
    return touched, np.bincount(inverse, change, len(touched))


def test_dents_are_clipped_to_the_grid_before_they_are_listed():
    """Drops inside, on the edge and off the grid give the same bits as listing each drop's whole square; a radius
    of thousands of cells on a small grid lists only the grid's vertices (it allocated gigabytes, a fuzzing
    review found: disturbance_radius 20 m at spacing 0.01 m)."""
    from systems.water_surface.waves import dents

    grid = make_grid(12, 0.5)
    rng = np.random.default_rng(4)
    centres = np.concatenate([rng.uniform(-3.0, 15.0, (40, 2)), [[0.0, 0.0], [11.0, 11.0], [-2.5, 5.0]]])
    heights = rng.uniform(0.01, 0.2, len(centres))
    for radius in (0.3, 0.5, 1.7, 4.0):
        got, want = dents(grid, centres, heights, radius), _dents_unclipped(grid, centres, heights, radius)
        assert got[0].tobytes() == want[0].tobytes() and got[1].tobytes() == want[1].tobytes()
    touched, change = dents(grid, centres[:2], heights[:2], 5000.0)  # 20,000 cells of reach: 1.6e9 listed before
    np.testing.assert_array_equal(touched, np.arange(144))
    np.testing.assert_allclose(change, -heights[:2].sum(), rtol=1e-5)  # exp(−r²/R²) ≈ 1 over the grid


def test_a_body_covering_every_vertex_leaves_the_water_finite():
    """A 4 × 4 m box over a 2.8 × 2.8 m pool: no vertex is water, so the mean level to keep was 0/0 and the whole
    pool turned NaN for good; it stays finite, also after the body is gone."""
    import warnings

    from systems.water_surface.geometry import empty_bodies
    from systems.water_surface.surface import step_water
    from tests.systems.water_surface.helpers import box, make_grid, make_state, water_config

    grid = make_grid(8, 0.4)
    cfg = water_config(resolution=[8, 8], spacing=0.4)
    state = make_state(grid)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for t in range(3):
            step_water(state, cfg, grid, box(0.01 * t, 0.0, half=(2.0, 0.5, 2.0)), 1 / 60)
            assert state.solid.all()
            assert np.isfinite(state.heights).all()
        for _ in range(3):
            step_water(state, cfg, grid, empty_bodies(), 1 / 60)
            assert np.isfinite(state.heights).all()
