"""The re-triangulated water mesh (section 2.2.4, fig. 3.2): a conforming triangulation of every square that
carries the body outline as edges, for any number of added points per square."""

from __future__ import annotations

import numpy as np
import pytest

from systems.water_surface.geometry import Bodies
import systems.water_surface.mesh as mesh_module
from systems.water_surface.mesh import WaterMesh, base_triangles, retriangulate, vertex_arrays, wire_arrays
from systems.water_surface.outline import added_points, cross_sections, nudge
from tests.systems.water_surface.helpers import box, make_grid, sphere

GRID = make_grid(26, 0.4)
ear_clip = mesh_module._ear_clip


def _mesh(bodies, segments=16):
    s = nudge(cross_sections(bodies, np.zeros(len(bodies)), GRID, segments))
    pts, _ = added_points(s, bodies.entities, GRID)
    return pts, retriangulate(26, 26, pts.uv, pts.kind, pts.segments)


def _check_conforming(pts, mesh):
    """Every triangle counter-clockwise with positive area, areas summing to the pool, every inner edge shared by
    exactly two triangles and every border edge by one (no T-junctions, no holes), every outline segment an edge."""
    gu, gv = np.meshgrid(np.arange(26.0), np.arange(26.0))
    uv = np.concatenate([np.stack([gu.ravel(), gv.ravel()], -1), pts.uv])
    t = mesh.triangles
    a, b, c = uv[t[:, 0]], uv[t[:, 1]], uv[t[:, 2]]
    area = 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    assert np.all(np.abs(area) > 0.0)
    assert np.sum(np.abs(area)) == pytest.approx(25.0 * 25.0, abs=1e-9)
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    mid = 0.5 * (uv[unique[:, 0]] + uv[unique[:, 1]])
    border = np.any((np.abs(mid) < 1e-9) | (np.abs(mid - 25.0) < 1e-9), axis=1)
    assert np.all(count[border] == 1) and np.all(count[~border] == 2)
    known = {tuple(e) for e in unique.tolist()}
    assert all(tuple(sorted(s)) in known for s in mesh.outline.tolist())
    _check_cells(uv, mesh)
    return area


def _check_cells(uv, mesh, n=26):
    """Square by square: every triangle strictly counter-clockwise and inside one square, the triangles of each
    square adding up to exactly its area (an overlap adds area, a hole removes it), every outline segment an edge of
    a triangle of its own square."""
    t = mesh.triangles
    a, b, c = uv[t[:, 0]], uv[t[:, 1]], uv[t[:, 2]]
    area = 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    assert np.all(area > 0.0)
    square = np.floor((a + b + c) / 3.0).astype(np.int64)
    low, high = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
    assert np.all(low >= square - 1e-12) and np.all(high <= square + 1 + 1e-12)
    cell = square[:, 1] * (n - 1) + square[:, 0]
    assert np.allclose(np.bincount(cell, area, (n - 1) ** 2), 1.0, rtol=0.0, atol=1e-12)
    edges = np.sort(np.stack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]], 1), axis=2)
    by_cell = {}
    for k, tri_edges in zip(cell.tolist(), edges.tolist()):
        by_cell.setdefault(k, set()).update(map(tuple, tri_edges))
    for s in mesh.outline.tolist():
        mid = np.floor(0.5 * (uv[s[0]] + uv[s[1]])).astype(np.int64)
        assert tuple(sorted(s)) in by_cell[int(mid[1] * (n - 1) + mid[0])], f"outline segment {s} not in the mesh"


def test_without_bodies_each_square_is_the_base_models_two_triangles():
    tris = base_triangles(3, 3, np.array([0]))
    assert tris.tolist() == [[0, 1, 3], [1, 4, 3]]  # (P[i,j], P[i+1,j], P[i,j+1]), (P[i+1,j], P[i+1,j+1], P[i,j+1])
    mesh = retriangulate(26, 26, np.zeros((0, 2)), np.zeros(0, np.int8), np.zeros((0, 2), np.int64))
    assert len(mesh.triangles) == 2 * 25 * 25 and len(mesh.cells) == 0


def test_fig_3_2_a_box_outline_is_in_the_mesh():
    pts, mesh = _mesh(box(0.1, 0.2, yaw=0.3))
    _check_conforming(pts, mesh)
    assert len(mesh.outline) == len(pts.uv) and len(mesh.cells) > 0
    assert len(mesh.triangles) > 2 * 25 * 25  # the crossed squares hold more triangles


@pytest.mark.parametrize("seed", range(16))
def test_random_boxes_and_spheres_triangulate_conformingly(seed):
    rng = np.random.default_rng(seed)
    if seed % 2:
        bodies = box(*rng.uniform(-6, 6, 2), half=tuple(rng.uniform(0.05, 2.0, 3)), yaw=rng.uniform(0, 6),
                     pitch=rng.uniform(-0.6, 0.6), roll=rng.uniform(-0.6, 0.6))
    else:
        bodies = sphere(*rng.uniform(-6, 6, 2), radius=rng.uniform(0.1, 2.0), y=rng.uniform(-0.5, 0.5))
    _check_conforming(*_mesh(bodies, segments=int(rng.integers(6, 40))))


def test_two_bodies_side_by_side():
    parts = [box(-1.3, 0.2, half=(0.9, 0.5, 0.7), yaw=0.5, entity=1), sphere(1.2, -0.4, radius=0.9, entity=2)]
    both = Bodies(*(np.concatenate([getattr(b, f) for b in parts]) for f in
                    ("entities", "shapes", "half", "radius", "position", "rotation")))
    pts, mesh = _mesh(both)
    assert set(pts.body.tolist()) == {0, 1}
    _check_conforming(pts, mesh)


def test_bodies_cut_by_the_pool_border_and_grid_aligned_boxes():
    for bodies in (box(-4.9, 0.0, yaw=0.3), sphere(4.9, 4.9, radius=1.0), box(0.6, 0.6, half=(1.2, 0.5, 0.8)),
                   box(0.0, 0.0, half=(0.4 * 2 ** 0.5, 0.5, 0.4 * 2 ** 0.5), yaw=np.pi / 4)):
        _check_conforming(*_mesh(bodies))


def test_a_body_inside_one_square_becomes_a_bridged_hole():
    for bodies in (box(0.0, 0.0, half=(0.08, 0.3, 0.05), yaw=0.4), sphere(0.03, -0.02, radius=0.12)):
        pts, mesh = _mesh(bodies)
        assert len(mesh.cells) == 1
        _check_conforming(pts, mesh)


def test_vertex_and_wire_arrays():
    pts, mesh = _mesh(box(0.1, 0.2, yaw=0.3))
    heights = np.zeros((26, 26))
    heights[:, 13:] = 0.1  # a step: the normals lean away from it
    positions, normals = vertex_arrays(GRID, heights, pts.uv, np.full(len(pts.uv), 0.05))
    assert positions.shape == (26 * 26 + len(pts.uv), 3)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
    assert normals[13 * 26 + 12, 0] < 0.0 and normals[0, 0] == 0.0
    wire = wire_arrays(positions, mesh)
    assert wire.shape == (2 * (3 * len(mesh.triangles) + len(mesh.outline)), 6)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_compiled_vertex_records_are_the_numpy_arrays_bits(seed):
    """kernels.vertex_records (what the renderer uploads) against vertex_arrays concatenated and rounded to
    float32: the same bits, over random waves, added points on and off the grid, a grid not at the origin."""
    from systems.water_surface.kernels import vertex_records

    rng = np.random.default_rng(seed)
    pts, _ = _mesh(box(0.1 + 0.05 * seed, 0.2, yaw=0.3 * seed))
    heights = rng.normal(0.0, 0.05, (26, 26))
    uv = np.concatenate([pts.uv, [[0.0, 0.0], [25.0, 25.0], [-0.5, 3.2], [12.5, 30.0]]])
    point_heights = rng.normal(0.0, 0.05, len(uv))
    grid = make_grid(26, 0.4)
    grid = type(grid)(grid.nx, grid.nz, grid.h, grid.x0 - 3.7, grid.z0 + 1.3, grid.y0 + 0.25)
    positions, normals = vertex_arrays(grid, heights, uv, point_heights)
    expected = np.concatenate([positions, normals], axis=1).astype(np.float32)
    got = vertex_records(heights, grid.h, grid.x0, grid.z0, grid.y0, uv, point_heights)
    assert got.dtype == np.float32 and np.array_equal(got, expected)


def test_the_checks_catch_a_missing_outline_segment_an_overlap_and_a_hole():
    pts, mesh = _mesh(box(0.1, 0.2, yaw=0.3))
    uv = np.concatenate([np.stack(np.meshgrid(np.arange(26.0), np.arange(26.0)), -1).reshape(-1, 2), pts.uv])
    _check_cells(uv, mesh)
    last = len(mesh.triangles) - 1  # a triangle of a re-triangulated square
    for triangles in (np.delete(mesh.triangles, last, axis=0), np.concatenate([mesh.triangles, mesh.triangles[last:]])):
        with pytest.raises(AssertionError):  # a hole, an overlap
            _check_cells(uv, WaterMesh(triangles, mesh.cells, mesh.outline))
    plain = base_triangles(26, 26)  # tiles every square, but without the outline
    with pytest.raises(AssertionError, match="not in the mesh"):
        _check_cells(uv, WaterMesh(plain, mesh.cells, mesh.outline))


def test_a_face_no_vertex_of_which_sees_the_others_is_ear_clipped(monkeypatch):
    """Two notches from opposite sides (an S): no fan is valid, the face goes to the ear clipper."""
    calls = []
    monkeypatch.setattr(mesh_module, "_ear_clip", lambda *a: calls.append(a) or ear_clip(*a))
    ring = np.array([[0, 0], [0.25, 0], [0.3, 0.9], [0.35, 0], [1, 0], [1, 1], [0.75, 1], [0.7, 0.1], [0.65, 1],
                     [0, 1]], float)
    tris = mesh_module._triangulate(-1 - np.arange(10)[None, :], ring[None], np.array([10]))
    p = ring[-1 - tris]
    area = 0.5 * ((p[:, 1] - p[:, 0])[:, 0] * (p[:, 2] - p[:, 0])[:, 1]
                  - (p[:, 1] - p[:, 0])[:, 1] * (p[:, 2] - p[:, 0])[:, 0])
    assert len(calls) == 1 and len(tris) == 8
    assert np.all(area > 0) and np.isclose(area.sum(), 1.0 - 2 * 0.5 * 0.1 * 0.9)


def test_the_previous_mesh_is_reused_only_while_it_stays_valid():
    pts, mesh = _mesh(box(0.1, 0.2, yaw=0.3))
    for du, reused in ((1e-3, True), (0.37, False)):  # a nudge keeps the combinatorics; a longer move does not
        moved = box(0.1 + 0.4 * du, 0.2, yaw=0.3)
        s = nudge(cross_sections(moved, np.zeros(1), GRID, 16))
        p2, _ = added_points(s, moved.entities, GRID)
        again = retriangulate(26, 26, p2.uv, p2.kind, p2.segments, mesh)
        assert (again.triangles is mesh.triangles) == reused
        _check_conforming(p2, again)
    # same combinatorics, but a kept triangle is no longer counter-clockwise: the squares are triangulated afresh
    cut = len(mesh.triangles) - 1
    turned = mesh.triangles.copy()
    turned[cut] = turned[cut, ::-1]
    stale = WaterMesh(turned, mesh.cells, mesh.outline, mesh.key)
    fresh = retriangulate(26, 26, pts.uv, pts.kind, pts.segments, stale)
    assert fresh.triangles is not turned and fresh.key == mesh.key
    _check_conforming(pts, fresh)
