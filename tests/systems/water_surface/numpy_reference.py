"""The numpy water step as it was before the compiled kernels (systems/water_surface/kernels.py): the reference the
kernels are tested against, bit for bit (tests/systems/water_surface/test_kernels.py). Frozen copy of
``surface.step_water`` and the helpers it has since replaced, at commit a4a7906; it uses the package's numpy
functions (outline.py, waves.py, geometry.py, and surface.py's helpers the kernels left unchanged), which stay as
the readable statement of the method."""
from __future__ import annotations

import numpy as np

from components.water_surface import WaterState, WaterSurface
from systems.water_surface.geometry import F64, Bodies, Grid, all_of, bilinear_fields
from systems.water_surface.outline import (AddedPoints, Sections, added_points, coupling_pairs, cross_sections,
                                           cut_edges, nudge, outline_impulse, solid_vertices, through_bodies)
from systems.water_surface.surface import (StepReport, _disturb, _grid_step, _scratch, _slots, _solid_index,
                                           _water_mean, plane_levels)
from systems.water_surface.waves import courant_k, free_degree, propagate

__all__ = ["step_water"]


def _near(bodies: Bodies, grid: Grid, state: WaterState, depth: float) -> np.ndarray:
    """Bodies whose footprint overlaps the grid and whose vertical extent reaches the water (tracked a little
    early: from two half heights above the highest wave)."""
    extent = bodies.extent()
    centre = grid.to_uv(bodies.position[:, ::2])
    half = extent[:, ::2] / grid.h
    over = all_of((centre + half >= 0.0) & (centre - half <= (grid.nx - 1, grid.nz - 1)), axis=1)
    vertical, y = extent[:, 1], bodies.position[:, 1]
    low = y - 2.0 * vertical
    near = over & (y + vertical >= grid.y0 - depth)
    # y − 2·half ≤ (max height) + y0: any one height bounds the maximum from below, so it settles most bodies
    sure = low <= (float(state.heights.flat[0]) + grid.y0) + 1e-9
    if not all_of(sure[near], axis=None):
        near &= low <= (float(np.max(state.heights)) + grid.y0) + 1e-9
    return near


def _previous(state: WaterState, bodies: Bodies, width: int) -> tuple[Sections, np.ndarray]:
    """Each body's cross-section at t − 1 (padded to ``width``) and whether it had one."""
    known = state.body_entities
    if (len(known) == len(bodies) and state.polygons.shape[1] == width and len(state.polygon_counts) == len(known)
            and np.array_equal(known, bodies.entities)):  # the same bodies as last step: their sections as they are
        sections = Sections(state.polygons, state.polygon_counts, state.polygon_counts, state.polygon_counts)
        cached = state.section_edges
        if cached is not None and cached[0] is state.polygons:
            sections._edges = cached[1]
        return sections, np.ones(len(bodies), bool)
    polygons = np.zeros((len(bodies), width, 2))
    counts = np.zeros(len(bodies), np.int64)
    has = np.zeros(len(bodies), bool)
    if len(known) and len(bodies):
        sorter = np.argsort(known)
        pos = np.minimum(np.searchsorted(known, bodies.entities, sorter=sorter), len(known) - 1)
        src = sorter[pos]
        has = known[src] == bodies.entities
        w = min(width, state.polygons.shape[1])
        polygons[has, :w] = state.polygons[src[has], :w]
        counts[has] = np.minimum(state.polygon_counts[src[has]], w)
    return Sections(polygons, counts, counts, counts), has


def _carried(state: WaterState, points: AddedPoints, z: F64, zp: F64) -> tuple[F64, F64]:
    """N_z(t), N_z(t − 1) of the added points: carried over by key from the last step, or lifted onto the
    surface (eq. 2.2–2.4) for points that are new."""
    known = state.point_keys
    if len(known) == len(points) and len(state.point_heights) == len(known) and np.array_equal(known, points.keys):
        return state.point_heights, state.point_previous  # the same points as last step (read only)
    if not (len(known) and len(points)):
        heights, previous = bilinear_fields((z, zp), points.uv)
        return heights, previous
    sorter = np.argsort(known)
    src = sorter.take(np.minimum(np.searchsorted(known, points.keys, sorter=sorter), len(known) - 1))
    same = known.take(src) == points.keys
    heights, previous = state.point_heights.take(src), state.point_previous.take(src)
    if not all_of(same, axis=None):  # only the new points are lifted onto the surface
        new = (~same).nonzero()[0]
        heights[new], previous[new] = bilinear_fields((z, zp), points.uv.take(new, axis=0))
    return heights, previous


def step_water(state: WaterState, cfg: WaterSurface, grid: Grid, bodies: Bodies, dt: float,
               rng: np.random.Generator | None = None) -> StepReport:
    """Advance ``state`` by one fixed step ``dt`` with ``bodies`` at their new transforms."""
    k = courant_k(cfg.wave_speed, cfg.spacing, dt)
    if state.degree is None or state.degree.shape != state.heights.shape or state.coefficient_k != k:
        state.degree = free_degree(*state.heights.shape)
        state.coefficient = 2.0 - k * state.degree
        state.coefficient_k = k
    volume = _water_mean(state.heights, _solid_index(state))
    if cfg.disturbance_rate > 0.0 or state.splashes:
        _disturb(state, cfg, grid, dt, rng)
    z = state.heights
    if len(bodies):
        near = _near(bodies, grid, state, cfg.depth)
        if not all_of(near, axis=None):
            bodies = bodies.take(near)
    levels = plane_levels(z, state.solid, bodies, grid)
    plane_y = grid.y0 + levels
    sections = nudge(cross_sections(bodies, plane_y, grid, cfg.sphere_segments))
    report = StepReport(bodies, plane_y, sections)
    if cfg.wave_source == "outline":
        new, new_points, points, previous_points = _outline_step(state, cfg, grid, bodies, sections, levels,
                                                                 plane_y, k, report)
    else:
        new, new_points, points, previous_points = _grid_step(state, cfg, grid, bodies, plane_y, k, report)
    # Keep the water's volume: drops, impacts, points coming and going and vertices changing between water and
    # body move the mean level a little; shift it back (heights at t and t + 1 alike: no velocity).
    mean = _water_mean(new, _solid_index(state) if cfg.wave_source == "outline" else None)
    shift = volume - mean
    if shift != 0.0:
        z += shift
        previous_points = previous_points + shift
    if cfg.damping < 1.0:  # section 2.3.2, about the mean level of the water: new ← V + d·(new + shift − V)
        new *= cfg.damping
        new += volume - cfg.damping * mean
        new_points = volume + cfg.damping * (new_points - mean)
    elif shift != 0.0:
        new += shift
        new_points = new_points + shift
    state.previous, state.heights = z, new
    state.point_keys, state.point_uv, state.point_kind = points.keys, points.uv, points.kind
    state.point_heights, state.point_previous, state.segments = new_points, previous_points, points.segments
    state.body_entities = bodies.entities.copy()
    if cfg.wave_source != "outline":
        state.solid_index = None
    state.polygons, state.polygon_counts = report.sections.polygons, report.sections.counts
    state.section_edges = (report.sections.polygons, report.sections._edges)  # next step's D'(t − 1) edges
    state.last_raised = report.change
    report.points = points
    return report


def _outline_step(state, cfg, grid, bodies, sections, levels, plane_y, k, report):
    """The paper's method: added points on the outline make and reflect the waves."""
    z, zp = state.heights, state.previous
    points, sections = added_points(sections, bodies.entities, grid)
    report.sections = sections
    heights, previous = _carried(state, points, z, zp)
    before, has = _previous(state, bodies, sections.polygons.shape[1])
    change, _, raised, lowered = outline_impulse(points, sections, before, has, grid, cfg.outline_constant)
    solid, solid_body = solid_vertices(sections, grid)
    state.solid = np.zeros(z.shape, bool)
    state.solid.ravel()[solid] = True
    # the vertices inside bodies once each and ascending, as ``state.solid.nonzero()`` gives them (the water's
    # mean level sums them in this order): the scanlines sorted, unless bodies overlap
    if len(bodies) == 1:
        unique = solid
    elif np.count_nonzero(state.solid) == len(solid):
        unique = np.sort(solid)
    else:
        unique = state.solid.ravel().nonzero()[0]
    state.solid_index = (state.solid, unique)
    pairs = coupling_pairs(points, state.solid, grid, solid_mask=True, slots=_slots(state))
    pairs = through_bodies(points, sections.edges, grid, pairs)
    cut = cut_edges(points, state.solid, grid)
    new, new_points = propagate(z, zp, k, state.coefficient, state.degree, solid, pairs, heights, previous,
                                _scratch(state), reuse=True, solid_mask=state.solid, slots=_slots(state), cut=cut)
    # eq. 2.6 / 2.7: a displacement of the point (its height history moves with it, so no velocity is injected)
    new_points += change
    heights = heights + change
    if len(solid):  # inside the body: held at the plane S' (hidden under the body), no velocity
        held = levels[solid_body]
        new.ravel()[solid] = held
        z.ravel()[solid] = held
    report.change, report.raised, report.lowered, report.solid = change, raised, lowered, solid
    return new, new_points, points, heights

