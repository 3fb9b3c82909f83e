"""Figure 1 (procedural plants) and table 1 (automatic simplification to levels 1-3)."""

from __future__ import annotations

import numpy as np
import pytest

from systems.grass_field.geometry import (DRAW_GROUPS, FINE, KIND_LEAF, KIND_TUBE, build_level_meshes,
                                          compact_mesh, dot_spacing, level_geometry, plant_skeleton)
from systems.grass_field.layout import draw_field
from tests.systems.grass_field.helpers import paper_config


@pytest.fixture(scope="module")
def paper():
    cfg = paper_config()
    state = draw_field(cfg, np.random.default_rng(5))
    return cfg, state


def _stem_top(verts: np.ndarray, radius: float) -> float:
    near_axis = np.hypot(verts[:, 0], verts[:, 2]) <= radius * 1.001
    return float(verts[near_axis, 1].max())


def test_table1_stem_shapes_and_lengths(paper):
    cfg, state = paper
    skel = plant_skeleton(cfg, state, 0)
    full = skel.stem_nodes[-1, 1]
    r0 = 0.5 * cfg.stem_diameter
    tris0, lines0, pts0 = level_geometry(skel, cfg, 0)
    tris1, lines1, pts1 = level_geometry(skel, cfg, 1)
    tris2, lines2, pts2 = level_geometry(skel, cfg, 2)
    tris3, lines3, pts3 = level_geometry(skel, cfg, 3)
    # level 0 cylinder (stem_sides sides), level 1 square prism (4 sides): tubes only there
    segments = len(skel.stem_nodes) - 1
    tube0 = tris0[tris0[:, 7] == KIND_TUBE]
    tube1 = tris1[tris1[:, 7] == KIND_TUBE]
    assert len(tube0) // 3 >= segments * cfg.stem_sides * 2 * 0.8
    ring1 = np.unique(np.round(np.degrees(np.arctan2(tube1[:3 * 4 * 2, 2], tube1[:3 * 4 * 2, 0]))))
    assert len(ring1) == 4  # a square prism
    assert not (tris2[:, 7] == KIND_TUBE).any() and len(lines2) and not len(pts2)  # level 2: lines
    assert not (tris3[:, 7] == KIND_TUBE).any() and not len(lines3) and len(pts3)  # level 3: dots
    # stem length 100 / 80 / 60 / 40 %
    assert _stem_top(tube0[:, :3], r0) == pytest.approx(1.0 * full, rel=1e-6)
    assert _stem_top(tube1[:, :3], r0) == pytest.approx(0.8 * full, rel=1e-6)
    assert _stem_top(lines2[:, :3], 1e-9) == pytest.approx(0.6 * full, rel=1e-6)
    top3 = _stem_top(pts3[:, :3], 1e-9)
    assert 0.4 * full - dot_spacing(cfg) <= top3 <= 0.4 * full


def test_table1_leaf_subdivisions_fall(paper):
    cfg, state = paper
    skel = plant_skeleton(cfg, state, 1)
    leaf = [int((level_geometry(skel, cfg, k)[0][:, 7] == KIND_LEAF).sum() // 3) for k in range(4)]
    n_branch, span = len(skel.branch_nodes), skel.segments - skel.leaf_root
    expect = [n_branch * 2 * max(1, int(np.ceil(span * s))) for s in cfg.leaf_subdivisions]
    assert leaf == expect  # two triangles per quad (the tip quad's second one has zero area)
    assert leaf[0] > leaf[1] > leaf[2] > leaf[3]


def test_simplification_keeps_the_silhouette(paper):
    cfg, state = paper
    skel = plant_skeleton(cfg, state, 2)
    boxes = []
    for k in range(4):
        tris = level_geometry(skel, cfg, k)[0]
        leaves = tris[tris[:, 7] == KIND_LEAF][:, :3]
        boxes.append(np.concatenate([leaves.min(axis=0), leaves.max(axis=0)]))
    size = boxes[0][3:] - boxes[0][:3]
    for box in boxes[1:]:
        assert np.all(np.abs(box - boxes[0]) <= 0.05 * np.concatenate([size, size]) + 1e-6)
    # the coarse leaf points lie on the fine reference curve
    u = np.linspace(skel.leaf_root, skel.segments, 4)
    coarse = skel.sample(u)
    fine = skel.branch_nodes
    d = np.linalg.norm(coarse[:, :, None, :] - fine[:, None, :, :], axis=-1).min(axis=-1)
    assert d.max() < 0.5 * cfg.base_length / FINE


def test_levels_have_fewer_primitives_and_share_one_layout(paper):
    cfg, state = paper
    meshes = build_level_meshes(cfg, state)
    prims = np.stack([m.real_primitives for m in meshes])
    assert np.all(prims[:-1] > prims[1:])
    for m in meshes:  # one vertex count for all variants (padding) → one instanced draw per level and type
        assert m.vertices.shape[0] == cfg.plant_variants and len(m.triangles) % 3 == 0
        assert m.padded_primitives >= m.real_primitives.max()
    assert prims[0].mean() > 5 * prims[3].mean()


def test_tube_triangles_come_first_and_face_outwards(paper):
    """Levels 0-1 draw their closed tubes with back faces culled: the leading ``tube_triangles`` triangles must be
    exactly the tube sides, every real one wound counter-clockwise seen from outside (its normal along the
    vertices' radial normals), and the rest (two-sided leaves) no tube."""
    cfg, state = paper
    meshes = build_level_meshes(cfg, state)
    assert [m.tube_triangles > 0 for m in meshes] == [True, True, False, False]
    for m in meshes:
        tubes = m.triangles[:3 * m.tube_triangles].reshape(-1, 3)
        rest = m.triangles[3 * m.tube_triangles:]
        for verts in m.vertices.astype(np.float64):
            assert np.all(verts[tubes.ravel(), 7] == KIND_TUBE)
            assert not np.any(verts[rest, 7] == KIND_TUBE)
            p, n = verts[:, :3], verts[:, 4:7]
            face = np.cross(p[tubes[:, 1]] - p[tubes[:, 0]], p[tubes[:, 2]] - p[tubes[:, 0]])
            real = np.linalg.norm(face, axis=1) > 1e-12
            radial = n[tubes[:, 0]] + n[tubes[:, 1]] + n[tubes[:, 2]]
            assert np.all(np.einsum("ij,ij->i", face[real], radial[real]) > 0.0)


def test_figure1_parameters_shape_the_plant(paper):
    cfg, state = paper
    base = plant_skeleton(cfg, state, 0)
    taller = paper_config(base_length=6.0)
    skel = plant_skeleton(taller, draw_field(taller, np.random.default_rng(5)), 0)
    assert skel.stem_nodes[-1, 1] == pytest.approx(2 * base.stem_nodes[-1, 1])  # T_BASIS scales the plant
    bent = paper_config(branch_bend_deg=25.0)
    tip_up = base.branch_nodes[:, -1, 1].mean()
    tip_bent = plant_skeleton(bent, draw_field(bent, np.random.default_rng(5)), 0).branch_nodes[:, -1, 1].mean()
    assert tip_bent < tip_up  # TE_ANGLE bends the branches over
    assert len(base.branch_nodes) == state.variant_branch_count[0]  # T_NUM
    counts = state.variant_branch_count
    assert counts.min() >= cfg.branch_count - cfg.branch_count_jitter
    assert counts.max() <= cfg.branch_count + cfg.branch_count_jitter
    # TR_WIDTH narrowing by TR_SHORT and closing at the tip
    w = base.blade_width(np.array([base.leaf_root, base.leaf_root + 1.0, base.segments]))
    assert w[0] == pytest.approx(cfg.leaf_width)
    assert w[1] == pytest.approx(cfg.leaf_width * (1 - cfg.leaf_narrowing))
    assert w[2] == 0.0


def test_compact_mesh_keeps_every_primitive_that_covers_a_pixel(paper):
    """Without the shared topology's padding each variant keeps exactly its real primitives, in order (the
    same vertex data), the tubes before the leaves, and only the vertices they use: the pixels are those of the
    padded mesh (a collapsed triangle or line covers none, a repeated dot the pixel of its first copy)."""
    cfg, state = paper
    for m in build_level_meshes(cfg, state):
        c = compact_mesh(m)
        ends = np.append(c.vertex_base, len(c.vertices))
        assert np.all(np.diff(ends) < m.vertices.shape[1])  # the padding's vertices are gone
        tubes = 3 * m.tube_triangles
        padded = {"tubes": (m.triangles[:tubes], 3), "leaves": (m.triangles[tubes:], 3), "lines": (m.lines, 2),
                  "points": (m.points, 1)}
        for v in range(cfg.plant_variants):
            verts = m.vertices[v]
            own = c.vertices[ends[v]:ends[v + 1]]
            used = np.zeros(len(own), bool)
            for group in DRAW_GROUPS:
                index, k = padded[group]
                prims = verts[np.asarray(index).reshape(-1, k)]
                p = prims[..., :3].astype(np.float64)
                if k == 3:
                    real = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1) > 1e-12
                elif k == 2:
                    real = np.linalg.norm(p[:, 1] - p[:, 0], axis=1) > 1e-12
                else:
                    real = np.arange(len(prims)) < m.real_points[v]
                    if real.any():  # the padding repeats the last dot
                        assert np.all(prims[~real] == prims[real][-1])
                first, count = int(c.first[group][v]), int(c.count[group][v])
                local = c.index[first:first + count]
                assert np.array_equal(own[local].reshape(prims[real].shape), prims[real])
                used[local] = True
            assert used.all()  # no vertex is shaded for nothing
            assert (c.count["tubes"][v] + c.count["leaves"][v]) // 3 == m.real_triangles[v]
            assert c.count["lines"][v] // 2 == m.real_lines[v] and c.count["points"][v] == m.real_points[v]
        assert c.groups == [g for g in DRAW_GROUPS if any(c.count[g])]
