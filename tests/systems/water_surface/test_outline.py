"""The body outline in the water (sections 2.2.2–2.3.1): cross-sections, added points, nudging, the ±α·d(t)
wave source, and figures 3.4 / 3.5 (where the first wave rises: at the front corners, or under the body)."""

from __future__ import annotations

import numpy as np
import pytest

from systems.water_surface.geometry import EPS_LINE, Grid, empty_bodies, inside_polygons, polygon_area
from systems.water_surface.outline import added_points, cross_sections, nudge, outline_impulse
from systems.water_surface.surface import step_water
from tests.systems.water_surface.helpers import box, make_grid, make_state, sphere, water_config

DT = 1.0 / 60.0
GRID = make_grid(26, 0.4)


def _section(bodies, plane=0.0):
    return nudge(cross_sections(bodies, np.full(len(bodies), plane), GRID, 16))


def test_cross_section_of_an_upright_turned_box_is_its_footprint():
    s = _section(box(0.3, 0.2, half=(1.0, 0.5, 0.6), yaw=0.4))
    assert s.counts[0] == 4
    assert polygon_area(s.polygons, s.counts)[0] * GRID.h ** 2 == pytest.approx(2.0 * 1.2, rel=1e-6)


def test_cross_section_of_a_pitched_box_is_stretched():
    pitch = 0.3  # about x: the side faces lean, the slice is (2·hx) × (2·hz / cos θ)
    s = _section(box(0.05, 0.0, half=(1.0, 0.5, 0.6), pitch=pitch))  # corners off the grid lines
    assert s.counts[0] == 4
    assert polygon_area(s.polygons, s.counts)[0] * GRID.h ** 2 == pytest.approx(2.0 * 1.2 / np.cos(pitch), rel=1e-6)


def test_a_corner_down_box_gives_a_hexagon_and_a_sphere_its_circle():
    s = _section(box(0.0, 0.0, half=(0.8, 0.8, 0.8), pitch=np.arctan(1 / np.sqrt(2)), roll=np.pi / 4))
    assert s.counts[0] == 6
    s = _section(sphere(0.1, 0.0, radius=1.0, y=0.6))  # circle radius 0.8 in the plane y = 0
    area = polygon_area(s.polygons, s.counts)[0] * GRID.h ** 2
    assert area == pytest.approx(0.5 * 16 * 0.8 ** 2 * np.sin(2 * np.pi / 16), rel=1e-9)


def test_added_points_are_the_vertices_and_the_grid_edge_crossings():
    # A box 2.0 × 1.2 m with corners off the grid: it spans u ∈ (7.75, 12.75), v ∈ (10.5, 13.5)
    s = _section(box(0.1, 0.2, half=(1.0, 0.5, 0.6)))
    pts, _ = added_points(s, np.array([7]), GRID)
    uv = pts.uv
    assert np.sum(pts.kind == 2) == 4  # the polygon's vertices L'
    on_u, on_v = pts.kind == 0, pts.kind == 1
    assert np.sum(on_u) == 2 * 5 and np.sum(on_v) == 2 * 3  # u = 8..12 twice, v = 11..13 twice
    assert np.allclose(uv[on_u, 0], np.round(uv[on_u, 0])) and np.allclose(uv[on_v, 1], np.round(uv[on_v, 1]))
    assert len(pts.segments) == len(uv)  # a closed outline, in order
    step = uv[pts.segments[:, 1]] - uv[pts.segments[:, 0]]
    assert np.all(np.hypot(*step.T) < 1.0 + 1e-9)  # consecutive points never skip a grid line


def test_points_on_grid_lines_are_nudged_inwards():
    # Corners exactly on grid vertices: x ∈ [−0.6, 1.8], z ∈ [−0.2, 1.4] → (u, v) ∈ [11, 17] × [12, 16]
    raw = cross_sections(box(0.6, 0.6, half=(1.2, 0.5, 0.8)), np.zeros(1), GRID, 16)
    assert np.allclose(raw.polygons[0, :4], np.round(raw.polygons[0, :4]))  # on grid vertices before nudging
    s = nudge(raw)
    p = s.polygons[0, :4]
    assert np.all(np.abs(p - np.round(p)) > EPS_LINE)  # off every grid line now
    assert np.all(np.abs(p - raw.polygons[0, :4]) < 1e-3)  # moved only slightly ...
    assert inside_polygons(p, np.repeat(raw.polygons, 4, 0), np.repeat(raw.counts, 4), margin=0.0).all()  # inwards
    pts, _ = added_points(s, np.array([7]), GRID)
    corner = np.abs(pts.uv - np.round(pts.uv)).max(axis=1) < 1e-6
    assert not corner.any()  # no added point sits on a grid vertex
    assert len(pts.uv) == 4 + 2 * 5 + 2 * 3  # and no extra points: corners + crossings of the inner lines


def test_eq_2_6_and_2_7_raise_the_front_and_lower_the_back():
    before = _section(box(-0.03, 0.1))
    after = _section(box(0.0, 0.1))
    pts, after = added_points(after, np.array([7]), GRID)
    change, d, raised, lowered = outline_impulse(pts, after, before, np.array([True]), GRID, alpha=2.0)
    u = pts.uv[:, 0]
    vertex = pts.kind == 2
    front = u > (1.0 + 5.0) / 0.4 - 1e-3  # the front face x = 1.0 (u = (x + 5) / h)
    back = u < (-1.0 + 5.0) / 0.4 + 1e-3
    sides = ~front & ~back
    assert raised[front].all() and not lowered[front].any()  # eq. 2.6: N(t−1) inside D'(t)
    assert lowered[back & ~vertex].all() and not raised[back & ~vertex].any()  # eq. 2.7: N(t) inside D'(t−1)
    assert np.allclose(d[front | (back & ~vertex)], 0.03, atol=1e-4)  # d(t): how far the outline moved (eq. 2.5)
    # a rear corner glides along the old side: it is on both outlines, rise and fall cancel; so do the sides
    assert np.all(raised[sides | (back & vertex)] == lowered[sides | (back & vertex)])
    assert change[front].min() > change[sides].max() and change[back & ~vertex].max() < change[sides].min()
    assert change.sum() == pytest.approx(0.0, abs=1e-12)  # rises and falls of one body balance
    assert np.allclose(change[front] - change[sides].mean(), 2.0 * 0.03, atol=1e-4)


def _first_rise(mode: str):
    """Move a box at 1 m/s through still water; return where the water first rises, and the box then."""
    cfg = water_config(wave_source=mode, outline_constant=1.0)
    grid, state = make_grid(26, 0.4), make_state(make_grid(26, 0.4))
    for t in range(30):
        x = -2.0 + t * DT
        step_water(state, cfg, grid, box(x, 0.1, half=(1.0, 0.5, 0.6)), DT)
        h = np.where(state.solid, -np.inf, state.heights - np.median(state.heights))
        if h.max() > 1e-4:
            j, i = np.unravel_index(np.argmax(h), h.shape)
            return np.array([grid.x0 + i * grid.h, grid.z0 + j * grid.h]), x
    raise AssertionError("no wave rose")


def test_fig_3_5_outline_waves_rise_at_the_front_corners_outside_the_body():
    (px, pz), x = _first_rise("outline")
    front = x + 1.0
    inside = (x - 1.0 < px < x + 1.0) and (0.1 - 0.6 < pz < 0.1 + 0.6)
    assert not inside
    corners = np.array([[front, 0.1 - 0.6], [front, 0.1 + 0.6]])
    assert np.min(np.hypot(corners[:, 0] - px, corners[:, 1] - pz)) < 0.4 + 1e-9  # within h of a front corner


def test_fig_3_4_grid_waves_rise_under_the_body():
    (px, pz), x = _first_rise("grid")
    assert x - 1.0 < px < x + 1.0 and 0.1 - 0.6 < pz < 0.1 + 0.6  # a grid vertex under the body


def test_a_moving_body_raises_the_water_in_front_and_lowers_it_behind():
    cfg = water_config(outline_constant=1.0, damping=0.995)
    grid, state = make_grid(26, 0.4), make_state(make_grid(26, 0.4))
    for t in range(45):
        x = -2.0 + t * DT
        step_water(state, cfg, grid, box(x, 0.1, half=(1.0, 0.5, 0.6)), DT)
    xs = grid.x0 + np.arange(26) * grid.h
    zs = grid.z0 + np.arange(26) * grid.h
    band = (zs > 0.1 - 0.6) & (zs < 0.1 + 0.6)
    ahead = (xs > x + 1.0) & (xs < x + 1.0 + 0.8)
    behind = (xs < x - 1.0) & (xs > x - 1.0 - 0.8)
    water = ~state.solid
    assert state.heights[np.ix_(band, ahead)][water[np.ix_(band, ahead)]].mean() > 1e-3
    assert state.heights[np.ix_(band, behind)][water[np.ix_(band, behind)]].mean() < -1e-3


def test_vertices_inside_the_body_are_solid_and_reflect():
    cfg = water_config()
    grid, state = make_grid(26, 0.4), make_state(make_grid(26, 0.4))
    report = step_water(state, cfg, grid, box(0.1, 0.2, half=(1.0, 0.5, 0.6)), DT)
    assert len(report.solid) == 5 * 3  # u = 8..12, v = 11..13 inside
    assert state.solid.sum() == 15


@pytest.mark.parametrize("thickness", [0.15, 0.3])
def test_a_wall_thinner_than_h_reflects_a_wave(thickness):
    """A wall across the pool between two columns of vertices (none inside it): a plane pulse sent at it stays on
    its side. Before the grid edges across it and the coupling pairs through it were cut, 75 % of the pulse's
    energy went through (0.15 m and 0.3 m alike)."""
    energy = []
    for wall in (True, False):
        grid = Grid(40, 26, 0.4, -7.8, -5.0, 0.0)
        state = make_state(grid)
        cfg = water_config(resolution=[40, 26], damping=1.0)
        xs = grid.x0 + grid.h * np.arange(grid.nx)  # ... -0.2, 0.2 ...: the wall at x = 0 lies between them
        state.heights[...] = 0.05 * np.exp(-((xs + 4.0) / 0.8) ** 2)[None, :]
        state.previous[...] = state.heights
        bodies = box(0.0, 0.0, half=(thickness / 2, 0.5, 8.0)) if wall else empty_bodies()
        for _ in range(330):  # the right-going half has passed x = 0 and not yet come back from the far border
            step_water(state, cfg, grid, bodies, DT)
        if wall:
            assert not state.solid.any()
        energy.append(float((state.heights[:, xs > 0.6] ** 2).sum()))
    assert energy[0] < 0.01 * energy[1]
