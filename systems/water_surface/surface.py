"""One simulation step of a water surface with the bodies that cut it (the world-facing systems are in
``simulate.py``). The outline method runs as two compiled kernels (``kernels.py``: the arithmetic of the numpy
functions of ``outline.py`` and ``waves.py`` in the same order, so the same bits, in two calls instead of
hundreds of numpy calls); the older ``grid`` method stays in numpy.

Order inside a step (seeds/003): random drops and impact dents → the plane S' of each body (mean water height
under it) → cross-section D' (2.2.2), nudged (fig. 2.3) → added points (2.2.3) carrying their heights from the
last step (or lifted onto the surface, eq. 2.2–2.4, when new) → wave generation ±α·d(t) (eq. 2.5–2.7) computed
→ propagation (eq. 2.8–2.12) with the vertices inside bodies held as obstacles → ±α·d(t) added to the added
points' heights at t and t + 1 (a displacement, ``kernels.finish``; the grid feels it from the next step) →
volume kept → damping. With
``wave_source = "grid"`` the added points are replaced by the older column displacement (``grid_source``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from engine.exact import matmul
from components.water_surface import WaterState, WaterSurface
from systems.water_surface import kernels as K
from systems.water_surface.geometry import F64, I64, Bodies, Grid, all_of, any_of, bilinear, ranges, sum_of
from systems.water_surface.grid_source import column_depths
from systems.water_surface.outline import (EDGE_A, EDGE_B, SHARED_FACE, AddedPoints, Sections,
                                           cross_sections, nudge, sphere_ring)
from systems.water_surface.waves import courant_k, dents, free_degree, propagate

__all__ = ["StepReport", "plane_levels", "step_water"]


@dataclass
class StepReport:
    """What one step did (for tests, benchmarks and the debug view)."""

    bodies: Bodies
    plane_y: F64
    sections: Sections | None = None
    points: AddedPoints | None = None
    change: F64 = field(default_factory=lambda: np.zeros(0))  # ±α·d(t) per added point
    raised: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    lowered: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    solid: I64 = field(default_factory=lambda: np.zeros(0, np.int64))
    column_change: F64 | None = None  # 'grid' method: α·(b(t) − b(t−1)) per vertex


def plane_levels(z: F64, solid: np.ndarray, bodies: Bodies, grid: Grid) -> F64:
    """S'_z − y0 for each body: the mean height of the water vertices where it floats (section 2.2.2), in its
    footprint grown on every side by :func:`plane_margin`; the vertices that were inside a body at the last step
    are not water and do not count (unless nothing else is there: then they hold the last S'). A body whose window
    holds no vertex takes the height at its centre."""
    centre = grid.to_uv(bodies.position[:, ::2])
    half = bodies.horizontal_half() / grid.h
    half = half + plane_margin(half[:, 0], half[:, 1])[:, None]
    lo = np.maximum(np.ceil(centre - half), 0).astype(np.int64)
    hi = np.minimum(np.floor(centre + half), (grid.nx - 1, grid.nz - 1)).astype(np.int64)
    size = np.maximum(hi - lo + 1, 0)
    if len(bodies) <= _LOOP_BODIES:  # a few bodies: one slice mean each
        empty = ~all_of(size, axis=1)
        levels = bilinear(z, centre) if any_of(empty, axis=None) else np.empty(len(bodies))
        for b in (~empty).nonzero()[0]:
            window = (slice(lo[b, 1], hi[b, 1] + 1), slice(lo[b, 0], hi[b, 0] + 1))
            water = z[window][~solid[window]]
            levels[b] = water.mean() if len(water) else z[window].mean()
        return levels
    count = size[:, 0] * size[:, 1]  # many: every window vertex at once, summed per body
    body, offset = ranges(np.zeros(len(bodies), np.int64), count)
    dv, du = np.divmod(offset, size[:, 0].take(body))
    flat = (lo[:, 1].take(body) + dv) * grid.nx + lo[:, 0].take(body) + du
    height, water = z.ravel().take(flat), ~solid.ravel().take(flat)
    n_water = np.bincount(body, water, len(bodies))
    wet = np.bincount(body, np.where(water, height, 0.0), len(bodies)) / np.maximum(n_water, 1)
    every = np.bincount(body, height, len(bodies)) / np.maximum(count, 1)
    if all_of(n_water > 0, axis=None):
        return wet
    return np.where(n_water > 0, wet, np.where(count > 0, every, bilinear(z, centre)))


_LOOP_BODIES = 3
PLANE_MARGIN = 2.0  # S' window: the footprint grown by this many times its larger half size ...
PLANE_MARGIN_CELLS = 2.0  # ... and by at least this many grid cells


def plane_margin(half_u: F64, half_v: F64) -> F64:
    """How far (grid units) S' looks past a body's footprint of half sizes ``half_u``, ``half_v`` (grid units).

    Only the footprint (the paper's "where the body is") is mostly the body's own outline waves: S' then rises
    and falls with them, the vertices held under the body with it, and the buoyancy sampled from them pushes in
    phase with the motion. A box floating tilted onto an edge kept bobbing 0.25 m peak to peak at α = 1 on the
    paper's pool. In a window three times the body's size its own waves are a small share: the box settles to
    2 mm (see docs/effects/water_surface.md)."""
    return np.maximum(PLANE_MARGIN * np.maximum(half_u, half_v), PLANE_MARGIN_CELLS)


def _scratch(state: WaterState) -> F64:
    """A work array of the grid's shape kept with the state (not part of it)."""
    if state.scratch is None or state.scratch.shape != state.heights.shape:
        state.scratch = np.empty_like(state.heights)
    return state.scratch


def _slots(state: WaterState) -> I64:
    """An int64 work array kept with the state, one entry per vertex and per square of the grid padded by a
    border of squares (for grouping vertex indices and looking up squares)."""
    nz, nx = state.heights.shape
    if state.slots is None or state.slots.size != (nz + 2) * (nx + 3):
        state.slots = np.empty((nz + 2) * (nx + 3), np.int64)
    return state.slots


def _water_mean(field: F64, solid: I64 | None) -> float:
    """Mean height of the vertices that are water (all but the flat indices ``solid``); of all the vertices when
    bodies cover every one (no water to measure)."""
    if solid is None or len(solid) >= field.size:
        return float(field.mean())
    return float((sum_of(field, axis=None) - sum_of(field.ravel()[solid])) / (field.size - len(solid)))


def _solid_index(state: WaterState) -> I64 | None:
    """Flat indices of the vertices inside bodies (``state.solid``), None when there are none."""
    cached = state.solid_index
    if cached is not None and cached[0] is state.solid:
        index = cached[1]
    else:
        index = state.solid.ravel().nonzero()[0]
    return index if len(index) else None


def _disturb(state: WaterState, cfg: WaterSurface, grid: Grid, dt: float, rng: np.random.Generator | None) -> None:
    """Random drops (``disturbance_rate``) and pending impact dents, as displacements without velocity."""
    centres, heights, radius = [], [], max(cfg.disturbance_radius, grid.h)
    if cfg.disturbance_rate > 0.0 and rng is not None:
        n = int(rng.poisson(cfg.disturbance_rate * dt))
        centres.append(rng.uniform((0.0, 0.0), (grid.nx - 1, grid.nz - 1), size=(n, 2)))
        heights.append(cfg.disturbance_height * rng.uniform(0.5, 1.0, size=n))
    if state.splashes:
        splash = np.array(state.splashes, dtype=np.float64).reshape(-1, 3)
        centres.append(splash[:, :2])
        heights.append(splash[:, 2])
        state.splashes = []
    if centres:
        flat, change = dents(grid, np.concatenate(centres), np.concatenate(heights), radius)
        state.heights.ravel()[flat] += change
        state.previous.ravel()[flat] += change


def step_water(state: WaterState, cfg: WaterSurface, grid: Grid, bodies: Bodies, dt: float,
               rng: np.random.Generator | None = None, report: bool = True) -> StepReport | None:
    """Advance ``state`` by one fixed step ``dt`` with ``bodies`` at their new transforms. Returns what the step
    did (:class:`StepReport`), or None without ``report`` (the systems read only the state: the outline method
    then skips building the report's objects)."""
    k = courant_k(cfg.wave_speed, cfg.spacing, dt)
    if state.degree is None or state.degree.shape != state.heights.shape or state.coefficient_k != k:
        state.degree = free_degree(*state.heights.shape)
        state.coefficient = 2.0 - k * state.degree
        state.coefficient_k = k
    pending = cfg.disturbance_rate > 0.0 or bool(state.splashes)
    volume = K.water_mean(state.heights, _solid_flat(state)) if pending else 0.0
    if pending:  # the volume to keep is the water's before the drops
        _disturb(state, cfg, grid, dt, rng)
    z = state.heights
    n = len(bodies)
    measured, n_near, n_fallback, floats, flags = K.bodies_in_water(
        z, state.solid, _solid_flat(state), not pending, bodies.shapes, bodies.half, bodies.radius, bodies.position,
        bodies.rotation, grid.x0, grid.z0, grid.h, grid.y0, float(cfg.depth), _CORNERS_T, PLANE_MARGIN,
        PLANE_MARGIN_CELLS)
    local, levels = floats[:24 * n].reshape(n, 3, 8), floats[24 * n:]
    if not pending:
        volume = measured
    if n_near < n:
        near = flags[:n].view(np.bool_)
        bodies, local = bodies.take(near), local[near]
    if n_fallback:  # a huge window all inside bodies: its mean as numpy buffers it
        index = flags[n:].nonzero()[0]
        levels[index] = plane_levels(z, state.solid, bodies.take(index), grid)
    plane_y = grid.y0 + levels
    if cfg.wave_source == "outline":
        result = _outline_step(state, cfg, grid, bodies, local, levels, plane_y, k, volume, report)
    else:
        result = _grid_method_step(state, cfg, grid, bodies, levels, plane_y, k, volume)
        state.polygons, state.polygon_counts = result.sections.polygons, result.sections.counts
        state.last_raised = result.change
    state.body_entities = bodies.entities.copy()
    return result if report else None


def _solid_flat(state: WaterState) -> I64:
    """Flat indices of the vertices inside bodies, ascending (empty when there are none)."""
    index = _solid_index(state)
    return _NO_INDEX if index is None else index


_NO_INDEX = np.zeros(0, np.int64)
_NO_TABLE = np.zeros((0, 0, 9))


_CORNERS_T = np.ascontiguousarray(np.array([[sx, sy, sz] for sx in (-1.0, 1.0) for sy in (-1.0, 1.0)
                                            for sz in (-1.0, 1.0)]).T)  # (3, 8) box corners, coordinate-major


def _outline_step(state, cfg, grid, bodies, local, levels, plane_y, k, volume, report) -> StepReport | None:
    """The paper's method: added points on the outline make and reflect the waves (one kernel, kernels.py). The
    boxes' corners are rotated by engine.exact's matmul, as the numpy step does."""
    z, zp = state.heights, state.previous
    n = len(bodies)
    cached = state.section_edges is not None and state.section_edges[0] is state.polygons
    new = zp if zp.flags.c_contiguous and zp.flags.writeable else np.empty_like(z)
    floats, ints, small, state.solid, m, n_seg, n_solid, n_unique, width = K.outline_step(
        z, zp, k, state.degree, new, matmul(bodies.rotation, local), bodies.shapes, bodies.position,
        bodies.radius, plane_y, levels, sphere_ring(cfg.sphere_segments), EDGE_A, EDGE_B, SHARED_FACE, grid.x0,
        grid.z0, grid.h, bodies.entities,
        state.point_keys, state.point_heights, state.point_previous, state.body_entities, state.polygons,
        state.polygon_counts, state.section_edges[1] if cached else _NO_TABLE, cached, cfg.outline_constant, volume,
        cfg.damping, _slots(state))
    bw = n * width  # unpack (views): see kernels.outline_step
    uv, change = floats[:2 * m].reshape(m, 2), floats[2 * m:3 * m]
    polygons = floats[5 * m:5 * m + 2 * bw].reshape(n, width, 2)
    solid_at = 2 * m + 2 * n_seg  # ints: keys, body, segments, solid, unique, counts, features
    unique_at = solid_at + n_solid
    counts_at = unique_at + n_unique
    outline, counts = ints[2 * m:solid_at].reshape(n_seg, 2), ints[counts_at:counts_at + n]
    state.solid_index = (state.solid, ints[unique_at:counts_at])
    state.previous, state.heights = z, new
    state.point_keys, state.point_uv, state.point_kind = ints[:m], uv, small[:m]
    state.point_heights, state.point_previous, state.segments = floats[3 * m:4 * m], floats[4 * m:5 * m], outline
    state.section_edges = (polygons, floats[5 * m + 2 * bw:].reshape(n, width, 9))  # next step's D'(t − 1) edges
    state.polygons, state.polygon_counts, state.last_raised = polygons, counts, change
    if not report:  # the systems: nothing reads the report's objects
        return None
    features, flags = ints[counts_at + n:].reshape(2, n, width), small[m:].view(np.bool_)
    sections = Sections(polygons, counts, features[0], features[1])
    points = AddedPoints(uv, state.point_kind, state.point_keys, ints[m:2 * m], outline)
    return StepReport(bodies, plane_y, sections, points, change, flags[:m], flags[m:], ints[solid_at:unique_at])


def _grid_method_step(state, cfg, grid, bodies, levels, plane_y, k, volume) -> StepReport:
    """The older method (numpy): cross-sections for the record, the column displacement, volume and damping."""
    sections = nudge(cross_sections(bodies, plane_y, grid, cfg.sphere_segments))
    report = StepReport(bodies, plane_y, sections)
    new, new_points, points, previous_points = _grid_step(state, cfg, grid, bodies, plane_y, k, report)
    z = state.heights
    # Keep the water's volume: drops, impacts and the displaced columns move the mean level a little; shift it back
    # (heights at t and t + 1 alike: no velocity).
    mean = _water_mean(new, None)
    shift = volume - mean
    if shift != 0.0:
        z += shift
    if cfg.damping < 1.0:  # section 2.3.2, about the mean level of the water: new ← V + d·(new + shift − V)
        new *= cfg.damping
        new += volume - cfg.damping * mean
    elif shift != 0.0:
        new += shift
    state.previous, state.heights = z, new
    state.point_keys, state.point_uv, state.point_kind = points.keys, points.uv, points.kind
    state.point_heights, state.point_previous, state.segments = new_points, previous_points, points.segments
    state.solid_index = None
    state.section_edges = None
    report.points = points
    return report


def _grid_step(state, cfg, grid, bodies, plane_y, k, report):
    """The older method (figure 3.4): the change of submerged depth displaces the vertices under the body."""
    z, zp = state.heights, state.previous
    column = np.zeros(z.shape)
    flat, depth = column_depths(bodies, plane_y, grid)
    column.ravel()[flat] = depth
    before = state.column_depth.copy() if state.column_depth is not None else np.zeros(z.shape)
    new_body = ~np.isin(bodies.entities, state.body_entities)
    if new_body.any():  # a body that just appeared has no earlier depth: it starts making waves once it moves
        flat, depth = column_depths(bodies.take(new_body), plane_y[new_body], grid)
        before.ravel()[flat] += depth
    change = cfg.outline_constant * (column - before)
    z += change  # a displacement (with z(t − 1), so no velocity is injected)
    zp += change
    state.column_depth = column
    state.solid = np.zeros(z.shape, bool)
    new, _ = propagate(z, zp, k, state.coefficient, state.degree, scratch=_scratch(state), reuse=True)
    report.column_change = change
    return new, np.zeros(0), AddedPoints.empty(), np.zeros(0)
