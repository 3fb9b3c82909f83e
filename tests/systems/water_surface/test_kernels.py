"""The compiled water step (systems/water_surface/kernels.py) gives the same bits as the numpy step it replaced
(numpy_reference.py, a frozen copy) and as the numpy functions of outline.py / waves.py: gliding, turning and
bobbing boxes, spheres, many bodies (the summation order numpy used for more than 3 bodies, the sparse
neighbour search past 96 added points), box corners exactly on the plane, polygon vertices on grid lines, a plank
thinner than h (grid edges and coupling pairs across it cut)."""

from __future__ import annotations

import numpy as np
import pytest

from systems.water_surface import kernels as K
from systems.water_surface.geometry import Bodies
from systems.water_surface.outline import (added_points, coupling_pairs, cross_sections, cut_edges, nudge,
                                           outline_impulse, solid_vertices, through_bodies)
from systems.water_surface.surface import step_water
from systems.water_surface.waves import free_degree, propagate
from tests.systems.water_surface import numpy_reference as reference
from tests.systems.water_surface.helpers import box, make_grid, make_state, sphere, water_config

DT = 1.0 / 60.0


def _join(*parts: Bodies) -> Bodies:
    return Bodies(*(np.concatenate([getattr(p, f) for p in parts]) for f in
                    ("entities", "shapes", "half", "radius", "position", "rotation")))


def _gliding(t: int) -> Bodies:
    return box(-2.5 + 0.06 * t, 0.4 + 0.01 * t, half=(1.0, 0.5, 0.6), yaw=20.0 + 0.5 * t, pitch=6.0, roll=4.0,
               y=0.1 * np.sin(t / 6.0))


def _sphere(t: int) -> Bodies:
    return sphere(1.0 - 0.04 * t, -0.5, radius=0.7, y=0.3 * np.sin(t / 5.0))


def _many(t: int) -> Bodies:  # 6 bodies: > 3 (plane levels summed in order) and > 96 added points (sparse pairs)
    return _join(*(box(-3.5 + 1.4 * i + 0.03 * t, -2.0 + 0.9 * (i % 3), half=(0.6, 0.4, 0.35 + 0.1 * i),
                       yaw=30.0 * i + t, pitch=5.0 * (i % 2), entity=10 + i) for i in range(4)),
                 sphere(2.5, 2.5 - 0.05 * t, radius=0.8, y=0.1, entity=20),
                 sphere(-2.0 + 0.05 * t, 2.8, radius=0.5, y=-0.1, entity=21))


def _on_lines(t: int) -> Bodies:
    # an upright box on the grid lines, its bottom corners exactly on the plane (flat water: S' = 0): corners on
    # the plane (repeated L' dropped), vertices on grid lines and vertices (nudged), windows all inside the body
    return box(0.0, 0.0, half=(0.8, 0.3 if t < 10 else 0.5, 1.2), y=0.3 if t < 10 else 0.2, yaw=0.0 if t < 20 else 45.0)


def _plank(t: int) -> Bodies:  # thinner than h: grid edges across it and pairs through it are cut
    return box(-2.0 + 0.05 * t, 0.3, half=(0.06, 0.5, 2.0), yaw=25.0 + t, y=0.05 * np.sin(t / 4.0))


SCENES = {"gliding box": _gliding, "sphere": _sphere, "many bodies": _many, "on grid lines": _on_lines,
          "thin plank": _plank}


def _states(seed: int, flat: bool):
    grid = make_grid(26, 0.4)
    a, b = make_state(grid), make_state(grid)
    if not flat:
        rng = np.random.default_rng(seed)
        a.heights[...] = 0.02 * rng.standard_normal(a.heights.shape)
        a.previous[...] = a.heights + 0.002 * rng.standard_normal(a.heights.shape)
        b.heights[...], b.previous[...] = a.heights, a.previous
    return grid, a, b


_FIELDS = ("heights", "previous", "solid", "point_keys", "point_uv", "point_heights", "point_previous", "point_kind",
           "segments", "body_entities", "polygons", "polygon_counts")


@pytest.mark.parametrize("name", SCENES)
@pytest.mark.parametrize("damping", [0.99, 1.0])
def test_the_kernel_step_repeats_the_numpy_step_bit_for_bit(name, damping):
    grid, fast, slow = _states(3, flat=name == "on grid lines")
    cfg = water_config(damping=damping, outline_constant=1.3, sphere_segments=12)
    points = 0
    for t in range(40):
        bodies = SCENES[name](t)
        got = step_water(fast, cfg, grid, bodies, DT)
        want = reference.step_water(slow, cfg, grid, bodies, DT)
        for field in _FIELDS:
            np.testing.assert_array_equal(getattr(fast, field), getattr(slow, field), err_msg=f"{field}, step {t}")
        for field in ("change", "raised", "lowered", "solid", "plane_y"):
            np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=f"{field}, step {t}")
        points = max(points, len(fast.point_uv))
    assert points > 0 and fast.heights.std() > 0.0
    if name == "many bodies":
        assert points > K.DENSE_PAIRS  # the sparse pair search ran


def test_pairwise_sum_is_numpys_sum():
    rng = np.random.default_rng(1)
    for n in [0, 1, 7, 8, 9, 15, 16, 127, 128, 129, 300, 676, 1025, 65536, 70001]:
        a = rng.standard_normal(n) * 10.0 ** rng.integers(-4, 4, n)
        assert 0.0 + K.pairwise_sum(a, 0, n) == np.add.reduce(a), n


@pytest.mark.parametrize("shape", [(1, 1), (1, 6), (5, 1), (2, 2), (3, 8), (26, 26), (40, 17)])
def test_wave_grid_is_the_numpy_propagation(shape):
    rng = np.random.default_rng(2)
    z, zp = rng.standard_normal(shape), rng.standard_normal(shape)
    k = 0.23
    degree = free_degree(*shape)
    new = np.empty(shape)
    K.wave_grid(z, zp, k, new)
    np.testing.assert_array_equal(new, propagate(z, zp, k, 2.0 - k * degree, degree)[0])


def _sections(bodies, grid, segments=12):
    plane = np.zeros(len(bodies))
    numpy_sections = nudge(cross_sections(bodies, plane, grid, segments))
    width = numpy_sections.polygons.shape[1]
    polygons, counts = np.zeros((len(bodies), width, 2)), np.zeros(len(bodies), np.int64)
    vfeat, efeat = np.zeros((len(bodies), width), np.int64), np.zeros((len(bodies), width), np.int64)
    is_box = bodies.shapes == 0
    from systems.water_surface.outline import EDGE_A, EDGE_B, SHARED_FACE, sphere_ring
    from systems.water_surface.surface import _CORNERS_T
    from engine.exact import matmul
    corners = matmul(bodies.rotation, _CORNERS_T * bodies.half[:, :, None]) + bodies.position[:, :, None]
    K.box_sections(corners, plane, EDGE_A, EDGE_B, SHARED_FACE, grid.x0, grid.z0, grid.h, polygons, counts, vfeat,
                   efeat, is_box.nonzero()[0])
    K.sphere_sections(bodies.position, bodies.radius, plane, sphere_ring(segments), grid.x0, grid.z0, grid.h,
                      polygons, counts, vfeat, efeat, (~is_box).nonzero()[0])
    K.nudge(polygons, counts)
    return numpy_sections, (polygons, counts, vfeat, efeat)


@pytest.mark.parametrize("name", SCENES)
def test_outline_kernels_are_the_numpy_functions(name):
    grid = make_grid(26, 0.4)
    before, now = SCENES[name](3), SCENES[name](4)
    (old_sections, _), (sections, (polygons, counts, vfeat, efeat)) = _sections(before, grid), _sections(now, grid)
    for got, want in zip((polygons, counts, vfeat, efeat), (sections.polygons, sections.counts,
                                                            sections.vertex_feature, sections.edge_feature)):
        np.testing.assert_array_equal(got, want)
    points, shrunk = added_points(sections, now.entities, grid)
    uv, kind, keys, body, segments = K.added_points(polygons, counts, vfeat, efeat, now.entities, grid.nx, grid.nz)
    for got, want in zip((uv, kind, keys, body, segments, polygons),
                         (points.uv, points.kind, points.keys, points.body, points.segments, shrunk.polygons)):
        np.testing.assert_array_equal(got, want)
    old_sections = added_points(old_sections, before.entities, grid)[1]
    before_table = K.edge_table(old_sections.polygons, old_sections.counts)
    after_table = K.edge_table(polygons, counts)
    has = np.ones(len(now), bool)
    change, _, raised, lowered = outline_impulse(points, shrunk, old_sections, has, grid, 1.3)
    k_change, k_raised, k_lowered = K.outline_impulse(uv, body, before_table, old_sections.counts >= 3, after_table,
                                                      grid.h, 1.3, len(now))
    for got, want in zip((k_change, k_raised, k_lowered), (change, raised, lowered)):
        np.testing.assert_array_equal(got, want)
    solid, owner = solid_vertices(shrunk, grid)
    k_solid, k_owner = K.solid_vertices(after_table, counts, grid.nx, grid.nz)
    np.testing.assert_array_equal(k_solid, solid)
    np.testing.assert_array_equal(k_owner, owner)
    mask, unique = K.solid_mask(k_solid, grid.nz, grid.nx)
    np.testing.assert_array_equal(unique, mask.ravel().nonzero()[0])
    pairs = coupling_pairs(points, mask, grid, solid_mask=True)
    k_pairs = K.grid_pairs(uv, mask, grid.nx, grid.nz) + K.point_pairs(uv, grid.nx, grid.nz)
    for got, want in zip(k_pairs, pairs):
        np.testing.assert_array_equal(got, want)
    kept = through_bodies(points, shrunk.edges, grid, pairs)
    for got, want in zip(K.through_bodies(after_table, uv, body, *k_pairs, grid.nx), kept):
        np.testing.assert_array_equal(got, want)
    cut = cut_edges(points, mask, grid)
    for got, want in zip(K.cut_edges(uv, kind, mask, grid.nx, grid.nz), cut):
        np.testing.assert_array_equal(got, want)
    if name == "thin plank":  # both ran on something: edges across it, pairs through it
        assert len(cut[0]) > 0 and len(kept[0]) < len(pairs[0]) and len(kept[3]) < len(pairs[3])


def test_wave_bodies_matches_numpy_bits():
    """kernels.wave_bodies (gather_wave_bodies' sizes and matrices) == |scale| products and bodies.quat_to_matrix
    bit for bit: random, axis-aligned, identity, half-turn and unnormalised quaternions, negative
    and zero scales."""
    from systems.water_surface.bodies import quat_to_matrix

    rng = np.random.default_rng(3)
    quats = np.concatenate([rng.standard_normal((40, 4)), np.eye(4), -np.eye(4), [[0.5, 0.5, -0.5, 0.5]],
                            [[np.sqrt(0.5), 0.0, np.sqrt(0.5), 0.0]], [[0.0, 0.0, 0.0, 0.0]]])
    unit = quats[:40] / np.linalg.norm(quats[:40], axis=1, keepdims=True)
    quats = np.concatenate([quats, unit])
    n = len(quats)
    position, scale = rng.standard_normal((n, 3)), rng.uniform(-2.0, 2.0, (n, 3))
    scale[::7, 1] = 0.0
    half, radius = rng.uniform(0.0, 1.5, (n, 3)), rng.uniform(0.0, 1.0, n)
    out = K.wave_bodies(np.concatenate([position.ravel(), quats.ravel(), scale.ravel(), half.ravel()]), radius,
                        K.QUAT_TERMS)
    want = np.concatenate([(half * np.abs(scale)).ravel(), radius * np.abs(scale).max(axis=1), position.ravel(),
                           quat_to_matrix(quats).ravel()])
    assert out.tobytes() == want.tobytes()
    for b in range(n):  # one body at a time too (numpy's matmul takes another path for a single row)
        one = K.wave_bodies(np.concatenate([position[b], quats[b], scale[b], half[b]]), radius[b:b + 1], K.QUAT_TERMS)
        assert one[7:].tobytes() == quat_to_matrix(quats[b:b + 1]).ravel().tobytes()


def test_a_step_without_report_leaves_the_same_state():
    """step_water(..., report=False) (the systems' call) skips only the report: the state is the same bits."""
    grid, with_report, without = _states(5, flat=False)
    cfg = water_config(damping=0.99, outline_constant=1.3, sphere_segments=12)
    for t in range(25):
        bodies = _many(t)
        assert step_water(with_report, cfg, grid, bodies, DT) is not None
        assert step_water(without, cfg, grid, bodies, DT, report=False) is None
        for field in (*_FIELDS, "last_raised", "solid_index", "section_edges"):
            a, b = getattr(with_report, field), getattr(without, field)
            for x, y in zip(a, b) if isinstance(a, tuple) else [(a, b)]:
                np.testing.assert_array_equal(x, y, err_msg=f"{field}, step {t}")
    assert len(without.point_uv) > 0


def test_a_window_all_inside_a_body_falls_back_to_numpys_plane_level(monkeypatch):
    """A body whose S' window (> 8192 vertices; here the whole grid) was all inside it at the last step: its plane
    level is numpy's (the fallback of step_water), the same bits as the reference step; a far body is left out."""
    grid = make_grid(120, 0.4)
    fast, slow = make_state(grid), make_state(grid)
    rng = np.random.default_rng(9)
    fast.heights[...] = slow.heights[...] = 0.01 * rng.standard_normal(fast.heights.shape)
    cfg = water_config(resolution=[120, 120], damping=0.99)
    fallbacks = []
    bodies_in_water = K.bodies_in_water

    def spy(*args):
        result = bodies_in_water(*args)
        fallbacks.append(result[2])
        return result

    monkeypatch.setattr(K, "bodies_in_water", spy)
    for t in range(4):
        bodies = _join(box(0.3 + 0.05 * t, -0.2, half=(25.0, 1.0, 25.5), y=0.2),
                       box(0.0, 0.0, half=(1.0, 0.5, 1.0), y=50.0, entity=8))  # far above the water
        step_water(fast, cfg, grid, bodies, DT, report=False)
        reference.step_water(slow, cfg, grid, bodies, DT)
        for field in _FIELDS:
            np.testing.assert_array_equal(getattr(fast, field), getattr(slow, field), err_msg=f"{field}, step {t}")
    assert fallbacks[0] == 0 and all(fallbacks[1:]) and fast.solid.sum() > 8192
