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
1 at the tip), normal, kind (0 tube, 1 leaf, 2 line or dot).  Each level's triangles, lines and points of all
plant variants are padded to one length with degenerate primitives, so a whole level draws with one
instanced call per primitive type (the vertex shader fetches ``variant * count + gl_VertexID``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from components.grass_field import GrassFieldConfig, GrassFieldState

__all__ = ["FINE", "LEVELS", "PlantSkeleton", "LevelMesh", "plant_skeleton", "level_geometry",
           "build_level_meshes", "cell_primitives", "plant_extent", "dot_spacing"]

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


def tube(nodes: np.ndarray, radius: np.ndarray, side: np.ndarray, sides: int) -> np.ndarray:
    """Triangles of tubes around polylines: ``nodes`` (B, M+1, 3), ``radius`` (B, M+1), ``side`` (B, 3).

    ``sides = 4`` gives the square prism of level 1, more sides the cylinder of level 0.
    Returns (B * M * sides * 6, 8) vertices (a triangle list).
    """
    t = _tangents(nodes)
    s = side[:, None, :] - np.sum(side[:, None, :] * t, axis=-1, keepdims=True) * t
    s /= np.maximum(np.linalg.norm(s, axis=-1, keepdims=True), 1e-12)
    n = np.cross(t, s)
    ang = 2.0 * np.pi * (np.arange(sides) + 0.5) / sides
    radial = np.cos(ang)[None, None, :, None] * s[:, :, None, :] + np.sin(ang)[None, None, :, None] * n[:, :, None, :]
    ring = nodes[:, :, None, :] + radius[:, :, None, None] * radial  # (B, M+1, S, 3)
    verts = _vertices(ring, 0.0, radial, KIND_TUBE)
    m = nodes.shape[1] - 1
    i = np.arange(m)[:, None]
    j = np.arange(sides)[None, :]
    j1 = (j + 1) % sides
    a, bb, c, d = (i, j), (i, j1), (i + 1, j), (i + 1, j1)
    corners = [a, bb, c, bb, d, c]
    rows = np.stack([np.broadcast_to(r, (m, sides)) for r, _ in corners], axis=-1)  # (M, S, 6)
    cols = np.stack([np.broadcast_to(cc, (m, sides)) for _, cc in corners], axis=-1)
    tri = verts[:, rows, cols]  # (B, M, S, 6, 8)
    return tri.reshape(-1, VERTEX_FLOATS)


def ribbon(centres: np.ndarray, width: np.ndarray, side: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Leaf blades: ``centres`` (B, Q+1, 3), ``width`` (Q+1,), ``side`` (B, 3), colour parameter ``t`` (Q+1,).

    Returns (B * Q * 6, 8) vertices; the normal is the blade's upper face (the shader lights both faces).
    """
    tang = _tangents(centres)
    normal = np.cross(side[:, None, :], tang)
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    half = 0.5 * width[None, :, None] * side[:, None, :]
    left = _vertices(centres - half, t[None, :], normal, KIND_LEAF)
    right = _vertices(centres + half, t[None, :], normal, KIND_LEAF)
    tri = np.stack([left[:, :-1], right[:, :-1], left[:, 1:], right[:, :-1], right[:, 1:], left[:, 1:]], axis=2)
    return tri.reshape(-1, VERTEX_FLOATS)


def polyline(nodes: np.ndarray) -> np.ndarray:
    """GL_LINES vertices of polylines ``nodes`` (B, M+1, 3): (B * M * 2, 8)."""
    pairs = np.stack([nodes[:, :-1], nodes[:, 1:]], axis=2)
    return _vertices(pairs, 0.0, [0.0, 1.0, 0.0], KIND_LINE).reshape(-1, VERTEX_FLOATS)


def dots(nodes: np.ndarray, spacing: float) -> np.ndarray:
    """GL_POINTS along polylines ``nodes`` (B, M+1, 3), one every ``spacing`` of arc length (at least one)."""
    out = []
    for line in nodes:  # build time only: a handful of branches
        seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        total = cum[-1]
        if total <= 0.0:
            continue
        count = max(1, int(total // spacing))
        s = (np.arange(count) + 0.5) * (total / count)
        pts = np.column_stack([np.interp(s, cum, line[:, a]) for a in range(3)])
        out.append(_vertices(pts, 0.0, [0.0, 1.0, 0.0], KIND_LINE))
    return np.concatenate(out) if out else np.zeros((0, VERTEX_FLOATS))


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


def level_geometry(skel: PlantSkeleton, cfg: GrassFieldConfig, level: int) -> tuple[np.ndarray, np.ndarray,
                                                                                       np.ndarray]:
    """Table 1: the (triangles, lines, points) vertex lists of one plant variant at ``level`` 0..3."""
    subdiv = cfg.leaf_subdivisions[level]
    stem, stem_r = _truncate(skel.stem_nodes, skel.stem_radius, cfg.stem_length_fractions[level])
    n_branch = len(skel.branch_nodes)
    tris, lines, points = [], [], []
    # the part of each branch below the blade, drawn like the stem
    lower = None
    if skel.leaf_root > 1e-6:
        q = max(1, int(np.ceil(skel.leaf_root * subdiv)))
        u = np.linspace(0.0, skel.leaf_root, q + 1)
        lower = skel.sample(u)
        lower_r = np.broadcast_to(skel.branch_radius(u), (n_branch, q + 1))
    if level <= 1:
        sides = cfg.stem_sides if level == 0 else 4
        tris.append(tube(stem[None], stem_r[None], np.array([[1.0, 0.0, 0.0]]), sides))
        if lower is not None:
            tris.append(tube(lower, lower_r, skel.branch_side, sides))
    elif level == 2:
        lines.append(polyline(stem[None]))
        if lower is not None:
            lines.append(polyline(lower))
    else:
        spacing = dot_spacing(cfg)
        points.append(dots(stem[None], spacing))
        if lower is not None:
            points.append(dots(lower, spacing))
    # the leaf blades
    q = max(1, int(np.ceil((skel.segments - skel.leaf_root) * subdiv)))
    u = np.linspace(skel.leaf_root, skel.segments, q + 1)
    t = (u - skel.leaf_root) / max(skel.segments - skel.leaf_root, 1e-9)
    tris.append(ribbon(skel.sample(u), skel.blade_width(u), skel.branch_side, t))
    cat = lambda parts: np.concatenate(parts) if parts else np.zeros((0, VERTEX_FLOATS))  # noqa: E731
    return cat(tris), cat(lines), cat(points)


# ----------------------------------------------------------------------------------------- per level
@dataclass
class LevelMesh:
    """One level's geometry for every plant variant, padded so all variants have the same vertex counts."""

    level: int
    triangles: np.ndarray  # (V, 3 * T, 8) float32
    lines: np.ndarray  # (V, 2 * L, 8) float32
    points: np.ndarray  # (V, P, 8) float32
    real_triangles: np.ndarray  # (V,) non-degenerate triangles per variant
    real_lines: np.ndarray  # (V,)
    real_points: np.ndarray  # (V,)

    @property
    def real_primitives(self) -> np.ndarray:
        """Primitives a plant of each variant really draws (the paper's count; padding excluded)."""
        return self.real_triangles + self.real_lines + self.real_points

    @property
    def padded_primitives(self) -> int:
        """Primitives one instance submits, padding included."""
        return self.triangles.shape[1] // 3 + self.lines.shape[1] // 2 + self.points.shape[1]


def _pad(parts: list[np.ndarray], group: int) -> np.ndarray:
    """Stack per-variant vertex lists into (V, n_max, 8), padding with degenerate primitives."""
    n_max = max(len(p) for p in parts)
    out = np.zeros((len(parts), n_max, VERTEX_FLOATS), dtype=np.float32)
    for i, p in enumerate(parts):
        out[i, :len(p)] = p
        if len(p) < n_max:
            out[i, len(p):] = p[0] if len(p) else 0.0  # zero area / zero length / a repeated dot
    assert n_max % group == 0
    return out


def _real_triangles(tri: np.ndarray) -> int:
    p = tri[:, :3].reshape(-1, 3, 3)
    area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    return int(np.count_nonzero(area > 1e-12))


def _real_lines(lines: np.ndarray) -> int:
    p = lines[:, :3].reshape(-1, 2, 3)
    return int(np.count_nonzero(np.linalg.norm(p[:, 1] - p[:, 0], axis=1) > 1e-12))


def build_level_meshes(cfg: GrassFieldConfig, state: GrassFieldState) -> list[LevelMesh]:
    """Levels 0-3 of every plant variant (level 0 from figure 1, levels 1-3 derived automatically)."""
    skeletons = [plant_skeleton(cfg, state, v) for v in range(cfg.plant_variants)]
    meshes = []
    for level in range(LEVELS):
        geo = [level_geometry(s, cfg, level) for s in skeletons]
        meshes.append(LevelMesh(
            level, _pad([g[0] for g in geo], 3), _pad([g[1] for g in geo], 2), _pad([g[2] for g in geo], 1),
            np.array([_real_triangles(g[0]) for g in geo]), np.array([_real_lines(g[1]) for g in geo]),
            np.array([len(g[2]) for g in geo])))
    return meshes


def plant_extent(meshes: list[LevelMesh]) -> tuple[float, float]:
    """(largest horizontal reach from the base, largest height) over all variants and levels, unscaled."""
    reach, height = 0.0, 0.0
    for m in meshes:
        for arr in (m.triangles, m.lines, m.points):
            if arr.size:
                reach = max(reach, float(np.sqrt(arr[..., 0] ** 2 + arr[..., 2] ** 2).max()))
                height = max(height, float(arr[..., 1].max()))
    return reach, height


def cell_primitives(plant_variant: np.ndarray, plants_per_cell: int, meshes: list[LevelMesh]) -> np.ndarray:
    """(C, 4): real primitives of each cell drawn at each geometric level (for the paper's table 4)."""
    per_level = [m.real_primitives[plant_variant].reshape(-1, plants_per_cell).sum(axis=1) for m in meshes]
    return np.stack(per_level, axis=1)
