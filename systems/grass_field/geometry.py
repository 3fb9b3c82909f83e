"""Procedural plant geometry (figure 1) and the automatic simplifications of table 1.  Pure numpy, no GL.

Level 0 is the plant the user designs with the figure-1 parameters; levels 1-3 are derived from the same
skeleton, keeping the silhouette rather than the detail (table 1):

    level  stem                 stem length   leaves
    0      cylinder             100 %         many subdivisions
    1      square prism          80 %         fewer
    2      line                  60 %         fewer
    3      dotted line           40 %         fewest

Skeleton.  The stem is a vertical chain of ``T_LONG`` segments of base length ``T_BASIS``, each ``TK_SHORT``
shorter and ``TK_VOLUM`` thinner than the one below.  ``T_NUM`` branches leave the base, tilted ``T_GRADI``
from the vertical at their azimuth; a branch has ``T_LONG`` segments of ``TE_DIFFE · T_BASIS`` shrinking by
``TE_SHORT`` and its tilt grows by ``TE_ANGLE`` per base length (the curve).  The reference curve is
integrated with :data:`FINE` steps per base length; every level samples points *on* it, so coarse levels
are inscribed in the fine curve.  The leaf blade runs from ``TR_ROOT`` of the branch to its tip, ``TR_WIDTH``
wide, narrowing by ``TR_SHORT`` per base length and closing over the last base length; below ``TR_ROOT`` the
branch is drawn like the stem (``TE_VOLUM`` thinning).

Vertices are 8 float32: position (plant-local, base at the origin), colour parameter (0 at the blade's root,
1 at the tip), normal, kind (0 tube, 1 leaf, 2 line or dot).  Meshes are indexed, and every plant variant of a
level shares one topology: stems, branches, rings and dots are padded to the largest count of any variant
with collapsed (zero-area, zero-length or repeated) elements, which keeps the level's structure comparable
across variants (its primitive counts, the tubes-first order).  For drawing, :func:`compact_mesh` drops the
padding again (about 30 % of a level's vertices and triangles): each variant keeps its real primitives and is
one command of a multi-draw indirect call.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from components.grass_field import GrassFieldConfig, GrassFieldState

__all__ = ["FINE", "LEVELS", "PlantSkeleton", "LevelParts", "LevelMesh", "plant_skeleton", "level_parts",
           "level_geometry", "build_level_meshes", "cell_primitives", "plant_extent", "dot_spacing", "DRAW_GROUPS",
           "CompactMesh", "compact_mesh"]

FINE = 8  # integration steps per base length of the reference curve
LEVELS = 4  # geometric levels 0..3
VERTEX_FLOATS = 8
KIND_TUBE, KIND_LEAF, KIND_LINE = 0.0, 1.0, 2.0


@dataclass
class PlantSkeleton:
    """The level-independent shape of one plant variant (plant-local coordinates, y up)."""

    stem_nodes: np.ndarray  # (S + 1, 3)
    stem_radius: np.ndarray  # (S + 1,)
    branch_nodes: np.ndarray  # (B, n * FINE + 1, 3) reference curves
    branch_side: np.ndarray  # (B, 3) horizontal unit vector across each blade
    segments: int  # n = T_LONG of this variant
    leaf_root: float  # u where the blade starts, in base lengths
    base_radius: float  # stem radius at the base
    branch_thinning: float
    leaf_width: float
    leaf_narrowing: float

    def sample(self, u: np.ndarray) -> np.ndarray:
        """Points on every branch's reference curve at arc parameters ``u`` (base lengths): (B, len(u), 3)."""
        f = np.clip(np.asarray(u, dtype=np.float64) * FINE, 0.0, self.segments * FINE)
        i0 = np.minimum(np.floor(f).astype(np.int64), self.segments * FINE - 1)
        t = (f - i0)[None, :, None]
        return self.branch_nodes[:, i0] * (1.0 - t) + self.branch_nodes[:, i0 + 1] * t

    def branch_radius(self, u: np.ndarray) -> np.ndarray:
        """TE_VOLUM: radius of a branch at ``u`` (the first segment is already one step thinner)."""
        return self.base_radius * (1.0 - self.branch_thinning) ** (1.0 + np.asarray(u, dtype=np.float64))

    def blade_width(self, u: np.ndarray) -> np.ndarray:
        """TR_WIDTH narrowing by TR_SHORT per base length, closing linearly over the last base length."""
        u = np.asarray(u, dtype=np.float64)
        width = self.leaf_width * (1.0 - self.leaf_narrowing) ** np.maximum(u - self.leaf_root, 0.0)
        return width * np.clip(self.segments - u, 0.0, 1.0)


def plant_skeleton(cfg: GrassFieldConfig, state: GrassFieldState, variant: int) -> PlantSkeleton:
    """Build the skeleton of plant variant ``variant`` from its jittered figure-1 parameters."""
    n = int(state.variant_segments[variant])
    b = int(state.variant_branch_count[variant])
    base = float(state.variant_base_length[variant])
    r0 = 0.5 * cfg.stem_diameter
    k = np.arange(n + 1, dtype=np.float64)
    stem_len = base * (1.0 - cfg.stem_shortening) ** k[:-1]
    stem_y = np.concatenate([[0.0], np.cumsum(stem_len)])
    stem = np.column_stack([np.zeros(n + 1), stem_y, np.zeros(n + 1)])
    stem_radius = r0 * (1.0 - cfg.stem_thinning) ** k

    tilt0 = state.variant_tilt[variant, :b]
    azimuth = state.variant_azimuth[variant, :b]
    steps = np.arange(n * FINE, dtype=np.float64)
    seg_len = base * cfg.branch_length_ratio * (1.0 - cfg.branch_shortening) ** np.floor(steps / FINE)
    tilt = np.clip(tilt0[:, None] + np.radians(cfg.branch_bend_deg) * (steps[None, :] + 0.5) / FINE,
                   0.0, np.radians(170.0))
    ca, sa = np.cos(azimuth)[:, None], np.sin(azimuth)[:, None]
    st, ct = np.sin(tilt), np.cos(tilt)
    step = np.stack([st * ca, ct, st * sa], axis=-1) * (seg_len / FINE)[None, :, None]
    start = np.stack([r0 * np.cos(azimuth), np.zeros(b), r0 * np.sin(azimuth)], axis=-1)
    nodes = np.concatenate([start[:, None, :], start[:, None, :] + np.cumsum(step, axis=1)], axis=1)
    nodes[..., 1] = np.maximum(nodes[..., 1], 0.0)  # a drooping tip rests on the ground
    side = np.stack([-np.sin(azimuth), np.zeros(b), np.cos(azimuth)], axis=-1)
    return PlantSkeleton(stem, stem_radius, nodes, side, n, cfg.leaf_root * n, r0, cfg.branch_thinning,
                         cfg.leaf_width, cfg.leaf_narrowing)


# ------------------------------------------------------------------------------------------ primitives
def _vertices(pos: np.ndarray, t: np.ndarray, normal: np.ndarray, kind: float) -> np.ndarray:
    """Pack (..., 3) positions, (...) colour parameters and (..., 3) normals into (..., 8) vertices."""
    t = np.broadcast_to(t, pos.shape[:-1])
    normal = np.broadcast_to(normal, pos.shape)
    out = np.empty(pos.shape[:-1] + (VERTEX_FLOATS,), dtype=np.float64)
    out[..., 0:3] = pos
    out[..., 3] = t
    out[..., 4:7] = normal
    out[..., 7] = kind
    return out


def _tangents(nodes: np.ndarray) -> np.ndarray:
    d = np.gradient(nodes, axis=-2) if nodes.shape[-2] > 1 else np.broadcast_to([0.0, 1.0, 0.0], nodes.shape)
    length = np.linalg.norm(d, axis=-1, keepdims=True)
    return np.where(length > 1e-12, d / np.maximum(length, 1e-12), [0.0, 1.0, 0.0])


# ------------------------------------------------------------------------------------------ level parts
@dataclass
class LevelParts:
    """The pieces of one plant variant at one level (table 1), before meshing.

    ``stem`` (R, 3) and ``stem_radius`` (R,): the shortened stem; ``lower`` (B, Qb+1, 3) and ``lower_radius``:
    the branches below the blade (None when TR_ROOT = 0); ``leaf`` (B, Q+1, 3), ``leaf_width`` and ``leaf_t``
    (Q+1,): the blades; ``dots`` (D, 3): the level-3 dotted lines; ``side`` (B, 3): across each blade.
    """

    level: int
    stem: np.ndarray
    stem_radius: np.ndarray
    lower: np.ndarray | None
    lower_radius: np.ndarray | None
    leaf: np.ndarray
    leaf_width: np.ndarray
    leaf_t: np.ndarray
    dots: np.ndarray
    side: np.ndarray


def _truncate(nodes: np.ndarray, radius: np.ndarray, fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """Keep the first ``fraction`` of a polyline's length (table 1: the stem is shortened)."""
    seg = np.linalg.norm(np.diff(nodes, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    cut = fraction * cum[-1]
    keep = cum < cut - 1e-9
    end = np.array([np.interp(cut, cum, nodes[:, a]) for a in range(3)])
    return np.vstack([nodes[keep], end]), np.append(radius[keep], np.interp(cut, cum, radius))


def dot_spacing(cfg: GrassFieldConfig) -> float:
    """World spacing of the level-3 dots: ``dot_spacing_pixels`` pixels at the 2⇄3 switch (P = L px per L)."""
    return cfg.dot_spacing_pixels * cfg.length_of_interest / cfg.level_thresholds[2]


def _dots(lines: np.ndarray, spacing: float) -> np.ndarray:
    """Points along polylines ``lines`` (B, M+1, 3), one every ``spacing`` of arc length (at least one each)."""
    out = []
    for line in lines:  # build time only: a handful of polylines
        cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
        if cum[-1] <= 0.0:
            continue
        count = max(1, int(cum[-1] // spacing))
        s = (np.arange(count) + 0.5) * (cum[-1] / count)
        out.append(np.column_stack([np.interp(s, cum, line[:, a]) for a in range(3)]))
    return np.concatenate(out) if out else np.zeros((0, 3))


def level_parts(skel: PlantSkeleton, cfg: GrassFieldConfig, level: int) -> LevelParts:
    """Table 1 for one plant variant: stem length and shape, leaf subdivisions, dotted lines at level 3."""
    subdiv = cfg.leaf_subdivisions[level]
    stem, stem_r = _truncate(skel.stem_nodes, skel.stem_radius, cfg.stem_length_fractions[level])
    n_branch = len(skel.branch_nodes)
    lower = lower_r = None
    if skel.leaf_root > 1e-6:
        qb = max(1, int(np.ceil(skel.leaf_root * subdiv)))
        u = np.linspace(0.0, skel.leaf_root, qb + 1)
        lower = skel.sample(u)
        lower_r = np.broadcast_to(skel.branch_radius(u), (n_branch, qb + 1)).copy()
    q = max(1, int(np.ceil((skel.segments - skel.leaf_root) * subdiv)))
    u = np.linspace(skel.leaf_root, skel.segments, q + 1)
    t = (u - skel.leaf_root) / max(skel.segments - skel.leaf_root, 1e-9)
    dots = np.zeros((0, 3))
    if level == 3:
        spacing = dot_spacing(cfg)
        dots = _dots(stem[None], spacing)
        if lower is not None:
            dots = np.vstack([dots, _dots(lower, spacing)])
    return LevelParts(level, stem, stem_r, lower, lower_r, skel.sample(u), skel.blade_width(u), t, dots,
                      skel.branch_side)


# ------------------------------------------------------------------------------------------- meshing
@dataclass(frozen=True)
class _Dims:
    """The shared topology of a level: counts every variant is padded to."""

    level: int
    sides: int  # tube sides (0: no tubes at this level)
    stem: int  # stem nodes
    branches: int
    lower: int  # nodes of each branch below the blade (0: none)
    leaf: int  # nodes along each blade
    dots: int

    def blocks(self) -> dict[str, tuple[int, int]]:
        """Vertex ranges (start, count) of each block in a variant's vertex array."""
        sizes = [("stem", self.stem * max(self.sides, 1)), ("lower", self.branches * self.lower * max(self.sides, 1)),
                 ("leaf", self.branches * self.leaf * 2), ("dots", self.dots)]
        out, start = {}, 0
        for name, size in sizes:
            out[name] = (start, size)
            start += size
        return out

    @property
    def vertices(self) -> int:
        return sum(size for _, size in self.blocks().values())


def _dims(parts: list[LevelParts], cfg: GrassFieldConfig, branches: int) -> _Dims:
    level = parts[0].level
    sides = cfg.stem_sides if level == 0 else 4 if level == 1 else 0
    lower = max((p.lower.shape[1] if p.lower is not None else 0) for p in parts)
    return _Dims(level, sides, max(len(p.stem) for p in parts), branches, lower,
                 max(p.leaf.shape[1] for p in parts), max(len(p.dots) for p in parts))


def _pad_rows(arr: np.ndarray, count: int, axis: int) -> np.ndarray:
    """Pad ``arr`` along ``axis`` to ``count`` by repeating its last element (collapsed, degenerate)."""
    n = arr.shape[axis]
    if n == count:
        return arr
    idx = np.minimum(np.arange(count), n - 1)
    return np.take(arr, idx, axis=axis)


def _pad_branches(arr: np.ndarray, count: int) -> np.ndarray:
    """Pad the branch axis (0) to ``count`` with branches collapsed onto the plant's base (all zeros)."""
    out = np.zeros((count,) + arr.shape[1:], dtype=np.float64)
    out[:len(arr)] = arr
    return out


def _ring_vertices(nodes: np.ndarray, radius: np.ndarray, side: np.ndarray, sides: int) -> np.ndarray:
    """Rings of tubes around polylines ``nodes`` (B, R, 3): (B, R, sides, 8) vertices with radial normals."""
    t = _tangents(nodes)
    s = side[:, None, :] - np.sum(side[:, None, :] * t, axis=-1, keepdims=True) * t
    s /= np.maximum(np.linalg.norm(s, axis=-1, keepdims=True), 1e-12)
    n = np.cross(t, s)
    ang = 2.0 * np.pi * (np.arange(sides) + 0.5) / sides
    radial = np.cos(ang)[None, None, :, None] * s[:, :, None, :] + np.sin(ang)[None, None, :, None] * n[:, :, None, :]
    return _vertices(nodes[:, :, None, :] + radius[:, :, None, None] * radial, 0.0, radial, KIND_TUBE)


def _tube_indices(start: int, tubes: int, rings: int, sides: int) -> np.ndarray:
    """Triangles between consecutive rings of ``tubes`` tubes laid out as (tube, ring, side), wound
    counter-clockwise seen from outside (the front faces face out: a tube can be drawn with back faces culled)."""
    b, i, j = np.meshgrid(np.arange(tubes), np.arange(rings - 1), np.arange(sides), indexing="ij")
    base = start + (b * rings + i) * sides
    j1 = (j + 1) % sides
    a, bb, c, d = base + j, base + j1, base + sides + j, base + sides + j1
    return np.stack([a, bb, c, bb, d, c], axis=-1).ravel()


def _strip_indices(start: int, strips: int, nodes: int) -> np.ndarray:
    """Triangles of ribbons laid out as (strip, node, left/right)."""
    b, i = np.meshgrid(np.arange(strips), np.arange(nodes - 1), indexing="ij")
    left = start + (b * nodes + i) * 2
    right, left1, right1 = left + 1, left + 2, left + 3
    return np.stack([left, right, left1, right, right1, left1], axis=-1).ravel()


def _line_indices(start: int, lines: int, nodes: int) -> np.ndarray:
    b, i = np.meshgrid(np.arange(lines), np.arange(nodes - 1), indexing="ij")
    first = start + b * nodes + i
    return np.stack([first, first + 1], axis=-1).ravel()


def _mesh_vertices(p: LevelParts, dims: _Dims) -> np.ndarray:
    """One variant's vertices in the shared layout of ``dims``."""
    out = []
    if dims.sides:  # rings are built on the real nodes, then padded with copies of the last ring
        rings = _ring_vertices(p.stem[None], p.stem_radius[None], np.array([[1.0, 0.0, 0.0]]), dims.sides)
        out.append(_pad_rows(rings, dims.stem, 1).reshape(-1, 8))
    else:
        out.append(_vertices(_pad_rows(p.stem, dims.stem, 0), 0.0, [0.0, 1.0, 0.0], KIND_LINE))
    side = _pad_branches(p.side, dims.branches)  # missing branches collapse onto the base
    if dims.lower:
        if dims.sides:
            rings = _pad_rows(_ring_vertices(p.lower, p.lower_radius, p.side, dims.sides), dims.lower, 1)
            out.append(_pad_branches(rings, dims.branches).reshape(-1, 8))
        else:
            lower = _pad_branches(_pad_rows(p.lower, dims.lower, 1), dims.branches)
            out.append(_vertices(lower, 0.0, [0.0, 1.0, 0.0], KIND_LINE).reshape(-1, 8))
    leaf = _pad_branches(_pad_rows(p.leaf, dims.leaf, 1), dims.branches)
    width = _pad_rows(p.leaf_width, dims.leaf, 0)
    t = _pad_rows(p.leaf_t, dims.leaf, 0)
    normal = np.cross(side[:, None, :], _tangents(leaf))
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    half = 0.5 * width[None, :, None] * side[:, None, :]
    pair = np.stack([_vertices(leaf - half, t[None, :], normal, KIND_LEAF),
                     _vertices(leaf + half, t[None, :], normal, KIND_LEAF)], axis=2)
    out.append(pair.reshape(-1, 8))
    if dims.dots:
        dots = _pad_rows(p.dots, dims.dots, 0) if len(p.dots) else np.zeros((dims.dots, 3))
        out.append(_vertices(dots, 0.0, [0.0, 1.0, 0.0], KIND_LINE))
    return np.concatenate(out)


def _mesh_indices(dims: _Dims) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(triangles, lines, points) index lists of the shared layout; the tubes' triangles come first (see
    :func:`_tube_triangles`)."""
    blocks = dims.blocks()
    tris, lines = [], []
    if dims.sides:
        tris.append(_tube_indices(blocks["stem"][0], 1, dims.stem, dims.sides))
        if dims.lower:
            tris.append(_tube_indices(blocks["lower"][0], dims.branches, dims.lower, dims.sides))
    else:
        lines.append(_line_indices(blocks["stem"][0], 1, dims.stem))
        if dims.lower and dims.level == 2:
            lines.append(_line_indices(blocks["lower"][0], dims.branches, dims.lower))
    tris.append(_strip_indices(blocks["leaf"][0], dims.branches, dims.leaf))
    if dims.level == 3:
        lines = []  # level 3 draws its stems as dots
    points = np.arange(blocks["dots"][0], blocks["dots"][0] + dims.dots)
    cat = lambda parts: np.concatenate(parts).astype(np.int32) if parts else np.zeros(0, np.int32)  # noqa: E731
    return cat(tris), cat(lines), points.astype(np.int32)


def _tube_triangles(dims: _Dims) -> int:
    """How many triangles at the start of :func:`_mesh_indices`'s list belong to the closed tubes (levels 0-1:
    the stem and the branches below the blade)."""
    if not dims.sides:
        return 0
    return (dims.stem - 1) * dims.sides * 2 + dims.branches * max(dims.lower - 1, 0) * dims.sides * 2


def level_geometry(skel: PlantSkeleton, cfg: GrassFieldConfig, level: int) -> tuple[np.ndarray, np.ndarray,
                                                                                       np.ndarray]:
    """Table 1 for one plant variant, expanded: (triangle, line, point) vertex lists (n, 8)."""
    parts = level_parts(skel, cfg, level)
    dims = _dims([parts], cfg, len(skel.branch_nodes))
    verts = _mesh_vertices(parts, dims)
    tris, lines, points = _mesh_indices(dims)
    return verts[tris], verts[lines], verts[points]


# ----------------------------------------------------------------------------------------- per level
@dataclass
class LevelMesh:
    """One level's indexed geometry for every plant variant, in one shared topology."""

    level: int
    vertices: np.ndarray  # (V, n, 8) float32
    triangles: np.ndarray  # (3T,) int32 indices, shared by every variant
    lines: np.ndarray  # (2L,) int32
    points: np.ndarray  # (P,) int32
    real_triangles: np.ndarray  # (V,) non-degenerate triangles per variant
    real_lines: np.ndarray  # (V,)
    real_points: np.ndarray  # (V,)
    tube_triangles: int = 0  # the first triangles: tube sides, wound counter-clockwise seen from outside

    @property
    def real_primitives(self) -> np.ndarray:
        """Primitives a plant of each variant really draws (the paper's count; padding excluded)."""
        return self.real_triangles + self.real_lines + self.real_points

    @property
    def padded_primitives(self) -> int:
        """Primitives one instance submits, padding included."""
        return len(self.triangles) // 3 + len(self.lines) // 2 + len(self.points)


def _real_triangles(verts: np.ndarray, index: np.ndarray) -> int:
    if not len(index):
        return 0
    p = verts[index.reshape(-1, 3), :3]
    area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    return int(np.count_nonzero(area > 1e-12))


def _real_lines(verts: np.ndarray, index: np.ndarray) -> int:
    if not len(index):
        return 0
    p = verts[index.reshape(-1, 2), :3]
    return int(np.count_nonzero(np.linalg.norm(p[:, 1] - p[:, 0], axis=1) > 1e-12))


def build_level_meshes(cfg: GrassFieldConfig, state: GrassFieldState) -> list[LevelMesh]:
    """Levels 0-3 of every plant variant (level 0 from figure 1, levels 1-3 derived automatically)."""
    skeletons = [plant_skeleton(cfg, state, v) for v in range(cfg.plant_variants)]
    branches = max(len(s.branch_nodes) for s in skeletons)
    meshes = []
    for level in range(LEVELS):
        parts = [level_parts(s, cfg, level) for s in skeletons]
        dims = _dims(parts, cfg, branches)
        verts = np.stack([_mesh_vertices(p, dims) for p in parts]).astype(np.float32)
        tris, lines, points = _mesh_indices(dims)
        v64 = verts.astype(np.float64)
        meshes.append(LevelMesh(level, verts, tris, lines, points,
                                np.array([_real_triangles(v, tris) for v in v64]),
                                np.array([_real_lines(v, lines) for v in v64]),
                                np.array([len(p.dots) for p in parts]), _tube_triangles(dims)))
    return meshes


# ----------------------------------------------------------------------------------------- compact form
DRAW_GROUPS = ("tubes", "leaves", "lines", "points")  # tubes: closed, drawable with back faces culled


@dataclass
class CompactMesh:
    """One level's variants without the shared topology's padding: each variant keeps only the primitives that
    can cover a pixel (non-degenerate triangles and lines, its own dots) and the vertices they use.  Drawn with
    one indirect command per variant (base vertex, first index), so no instance runs the padding's vertices or
    sets up its collapsed triangles (about 30 % of a padded level)."""

    level: int
    vertices: np.ndarray  # (n, 8) float32: every variant's vertices, variant v's from vertex_base[v]
    vertex_base: np.ndarray  # (V,) int
    index: np.ndarray  # (I,) int32, relative to the variant's base vertex; the groups one after the other
    first: dict[str, np.ndarray]  # draw group -> (V,) first index of each variant's primitives
    count: dict[str, np.ndarray]  # draw group -> (V,) index count of each variant

    @property
    def groups(self) -> list[str]:
        """The draw groups any variant has primitives in, in draw order."""
        return [g for g in DRAW_GROUPS if self.count[g].any()]


def compact_mesh(mesh: LevelMesh) -> CompactMesh:
    """``mesh`` without its padding (see :class:`CompactMesh`); every variant draws the same pixels as in the
    shared topology (a collapsed triangle or line covers none, a repeated dot the pixel of the first)."""
    variants = len(mesh.vertices)
    tubes = 3 * mesh.tube_triangles
    lists = {"tubes": (mesh.triangles[:tubes], 3), "leaves": (mesh.triangles[tubes:], 3),
             "lines": (mesh.lines, 2), "points": (mesh.points, 1)}
    first = {g: np.zeros(variants, np.int64) for g in DRAW_GROUPS}
    count = {g: np.zeros(variants, np.int64) for g in DRAW_GROUPS}
    kept: dict[str, list[np.ndarray]] = {g: [] for g in DRAW_GROUPS}
    vertices, bases, base = [], [], 0
    for v in range(variants):
        verts = mesh.vertices[v]
        p = verts[:, :3].astype(np.float64)
        per_group = {}
        for g, (index, k) in lists.items():
            prim = np.asarray(index, dtype=np.int64).reshape(-1, k)
            if k == 3 and len(prim):
                keep = np.linalg.norm(np.cross(p[prim[:, 1]] - p[prim[:, 0]], p[prim[:, 2]] - p[prim[:, 0]]),
                                      axis=1) > 1e-12  # as _real_triangles
            elif k == 2 and len(prim):
                keep = np.linalg.norm(p[prim[:, 1]] - p[prim[:, 0]], axis=1) > 1e-12  # as _real_lines
            else:
                keep = np.arange(len(prim)) < int(mesh.real_points[v])  # the variant's own dots, then repeats
            per_group[g] = prim[keep].ravel()
        used = np.unique(np.concatenate(list(per_group.values()))) if any(len(x) for x in per_group.values()) \
            else np.zeros(0, np.int64)
        for g in DRAW_GROUPS:
            kept[g].append(np.searchsorted(used, per_group[g]))
        vertices.append(verts[used])
        bases.append(base)
        base += len(used)
    index, at = [], 0
    for g in DRAW_GROUPS:
        for v in range(variants):
            first[g][v], count[g][v] = at, len(kept[g][v])
            index.append(kept[g][v])
            at += len(kept[g][v])
    return CompactMesh(mesh.level, np.concatenate(vertices).astype(np.float32), np.array(bases, np.int64),
                       np.concatenate(index).astype(np.int32), first, count)


def plant_extent(meshes: list[LevelMesh]) -> tuple[float, float]:
    """(largest horizontal reach from the base, largest height) over all variants and levels, unscaled."""
    reach = max(float(np.hypot(m.vertices[..., 0], m.vertices[..., 2]).max()) for m in meshes)
    height = max(float(m.vertices[..., 1].max()) for m in meshes)
    return reach, height


def cell_primitives(plant_variant: np.ndarray, plants_per_cell: int, meshes: list[LevelMesh]) -> np.ndarray:
    """(C, 4): real primitives of each cell drawn at each geometric level (for the paper's table 4)."""
    per_level = [m.real_primitives[plant_variant].reshape(-1, plants_per_cell).sum(axis=1) for m in meshes]
    return np.stack(per_level, axis=1)
