"""Terrain rendering: a height field cut into square chunks, each drawn at a level of detail per view.

The grid is uploaded once (one vertex buffer).  Every chunk of ``CHUNK`` × ``CHUNK`` quads has one index range
per level ``l`` (every ``2^l``-th grid line, the chunk's last line always kept, so levels of one chunk share its
border vertices), laid out level-major so that neighbouring chunks drawn at one level merge into one draw call.
Per view and frame (numpy over chunks, no GL reads):

* chunks whose bounding box lies outside the view frustum are skipped;
* a chunk's level is the coarsest whose geometric error — the largest height difference between the full grid
  and the level's interpolated surface, computed once per chunk and level — projects to at most
  ``detail_pixels`` on screen at the chunk's nearest point (pixels per metre from the projection: constant for
  orthographic views, 1/distance for perspective ones), the screen-space error criterion of geomipmapping
  (de Boer 2000).  Shading does not ride on the vertices: diffuse and ambient light are baked per grid point
  into a texture at the height field's full resolution (:func:`shade_texels`; re-baked when the light or the
  colours change), so a coarse chunk keeps every bump of its lighting and only its silhouette and depth may
  move, by at most ``detail_pixels``.  In orthographic top views this lets the flat valley floor drop to a
  handful of triangles.  Chunks drawn at full detail (level 0), whose vertices are the baked grid points, read
  the baked light per vertex and interpolate the colour (Gouraud, the ``VERTEX_SHADE`` shader variant) instead
  of fetching the texture per pixel;
* cracks between neighbours at different levels are hidden by skirts: along every interior chunk edge a strip
  hangs from the edge vertices to copies lowered by the largest crack that edge can open (:func:`skirt_depths`),
  drawn with the edge's shading.

On a software rasteriser the terrain is bound by triangle setup, which llvmpipe runs on the calling thread, so
culling and coarser levels cut its cost nearly in proportion to the triangles skipped; the per-pixel texture
fetch that replaces per-vertex lighting runs on the rasteriser's threads (in the dust devil bench's view, at
lod_pixels 2, the terrain pass is mostly per-pixel work: 354 or 2744 triangles cost about the same, and the
Gouraud variant on the three full-detail chunks took ≈ 1 ms of ≈ 8 off the pass under load).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CHUNK = 16  # quads per chunk side; a power of two so that levels 0..log2(CHUNK) all fit exactly
VERTEX_FLOATS = 7  # position (3), normal (3), skirt depth (1)


@dataclass
class TerrainChunks:
    """CPU side of a chunked height-field mesh: vertices, indices, and per chunk/level index ranges."""

    vertices: np.ndarray  # (n, 7) float32
    indices: np.ndarray  # (m,) uint32, level-major: level 0 of every chunk, then level 1, ...
    first: np.ndarray  # (levels, chunks) int64: first index of a chunk's range at a level
    count: np.ndarray  # (levels, chunks) int64: number of indices
    box_min: np.ndarray  # (chunks, 3) local-space bounding boxes (skirts excluded)
    box_max: np.ndarray  # (chunks, 3)
    error: np.ndarray  # (levels, chunks): largest |height - level's interpolated height| (local units)
    quad_size: float  # grid spacing (local units) of level 0
    uv_scale: tuple[float, float] = (1.0, 1.0)  # local (x, z) -> shade texture coordinates: x * scale + offset,
    uv_offset: tuple[float, float] = (0.0, 0.0)  # so that texel centres sit on the grid points

    @property
    def levels(self) -> int:
        return self.first.shape[0]

    @property
    def chunks(self) -> int:
        return self.first.shape[1]


def _lines(start: int, stop: int, step: int) -> np.ndarray:
    """Grid lines ``start, start+step, ...`` of a chunk spanning [start, stop], with ``stop`` always included."""
    lines = np.arange(start, stop, step)
    return np.append(lines, stop)


def _grid_triangles(rows_idx: np.ndarray, cols_idx: np.ndarray, cols: int) -> np.ndarray:
    """Two triangles per quad of the sub-grid given by the chosen row and column lines."""
    r, c = np.meshgrid(rows_idx, cols_idx, indexing="ij")
    v = r * cols + c
    a, b, cc, d = v[:-1, :-1], v[1:, :-1], v[:-1, 1:], v[1:, 1:]
    return np.stack([a, b, cc, cc, b, d], axis=-1).ravel()


def _interpolation(fine: np.ndarray, coarse: np.ndarray) -> np.ndarray:
    """(len(fine), len(coarse)) matrix of linear interpolation weights from coarse grid lines to fine ones."""
    upper = np.clip(np.searchsorted(coarse, fine, side="right"), 1, len(coarse) - 1)
    lower = upper - 1
    t = (fine - coarse[lower]) / (coarse[upper] - coarse[lower])
    weights = np.zeros((len(fine), len(coarse)))
    rows = np.arange(len(fine))
    weights[rows, lower] = 1.0 - t
    weights[rows, upper] += t
    return weights


def level_error(h: np.ndarray, rows_idx: np.ndarray, cols_idx: np.ndarray, r0: int, c0: int) -> float:
    """Largest height difference between a chunk's full grid and its surface at a level (bilinear estimate)."""
    block = h[r0:rows_idx[-1] + 1, c0:cols_idx[-1] + 1]
    wr = _interpolation(np.arange(r0, rows_idx[-1] + 1), rows_idx)
    wc = _interpolation(np.arange(c0, cols_idx[-1] + 1), cols_idx)
    coarse = h[np.ix_(rows_idx, cols_idx)]
    return float(np.abs(block - wr @ coarse @ wc.T).max())


def _edge_error(profile: np.ndarray, levels: int) -> float:
    """Largest |height − its interpolation| along one chunk edge (a 1-D height profile) over every level."""
    fine = np.arange(len(profile))
    worst = 0.0
    for level in range(1, levels):
        coarse = _lines(0, len(profile) - 1, 1 << level)
        worst = max(worst, float(np.abs(profile - np.interp(fine, coarse, profile[coarse])).max()))
    return worst


def skirt_depths(h: np.ndarray, row_starts: np.ndarray, col_starts: np.ndarray, levels: int,
                 margin: float) -> np.ndarray:
    """(rows, cols) how far each vertex of an interior chunk edge hangs its skirt: the edge's largest crack.

    Along an edge shared by chunks at levels l1 < l2, both sides are linear between the finer level's vertices,
    where the finer side is exact; so the gap is at most max |h − I_l2(h)| over the edge's vertices, the 1-D
    interpolation error of the coarser level along that edge.  A skirt that deep (plus ``margin``) closes every
    crack, and no deeper: tall skirts cost fill (hidden behind the ground, but still rasterised and depth tested).
    A vertex on two edges (a chunk corner) takes the deeper.
    """
    rows, cols = h.shape
    depth = np.zeros((rows, cols))
    col_edges = list(col_starts) + [cols - 1]
    row_edges = list(row_starts) + [rows - 1]
    for r in row_starts[1:]:  # interior row lines, one segment per chunk column
        for c0, c1 in zip(col_edges[:-1], col_edges[1:]):
            seg = np.s_[r, c0:c1 + 1]
            depth[seg] = np.maximum(depth[seg], _edge_error(h[seg], levels) + margin)
    for c in col_starts[1:]:
        for r0, r1 in zip(row_edges[:-1], row_edges[1:]):
            seg = np.s_[r0:r1 + 1, c]
            depth[seg] = np.maximum(depth[seg], _edge_error(h[seg], levels) + margin)
    return depth


def _skirt_triangles(edge: np.ndarray, skirt_of: np.ndarray) -> np.ndarray:
    """A strip of two triangles per edge segment, from the edge vertices down to their skirt copies."""
    a, b = edge[:-1], edge[1:]
    sa, sb = skirt_of[a], skirt_of[b]
    return np.stack([a, b, sa, b, sb, sa], axis=-1).ravel()


def grid_normals(field) -> np.ndarray:
    """(rows, cols, 3) unit normals of a height field's grid points (central differences)."""
    h = np.asarray(field.heights, np.float64)
    dz, dx = np.gradient(h, field.spacing)
    normals = np.stack([-dx, np.ones_like(h), -dz], axis=-1)
    return normals / np.linalg.norm(normals, axis=-1, keepdims=True)


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def shade_texels(field, model: np.ndarray, colors, sun_dir, sun_color, ambient: float, sky_top,
                 sky_horizon, sun_visibility: np.ndarray | None = None) -> np.ndarray:
    """(rows, cols, 4) float32: the diffuse and ambient light of every grid point times its albedo, as
    ``lit.glsl``'s ``shade`` computes them (the specular term, view-dependent and small, stays per vertex);
    alpha: ``sun_visibility``, the share of the sun reaching each point past the terrain's own hills
    (engine/render/terrain_shadow.py; None: 1 everywhere), which also scales the sun's diffuse term.

    Albedo: the ``colors`` ramp by the point's height normalised over the field, darkened by 30 % towards rock
    on slopes (normal·up from 0.85 down to 0.55).  Light: Lambert from the sun plus the hemisphere ambient
    between ``sky_horizon`` × 0.35 and ``sky_top``.  Normals are turned by the model matrix's upper 3 × 3, as
    the vertex shader turns them.
    """
    h = np.asarray(field.heights, np.float64)
    ramp = np.asarray(colors, np.float64).reshape(-1, 3)
    if len(ramp) == 1:
        ramp = np.concatenate([ramp, ramp])
    lo, hi = float(h.min()), float(h.max())
    x = np.clip((h - lo) / max(hi - lo, 1e-4), 0.0, 1.0) * (len(ramp) - 1)
    i = np.minimum(np.floor(x), len(ramp) - 2).astype(np.int64)
    albedo = ramp[i] + (ramp[i + 1] - ramp[i]) * (x - i)[..., None]
    n = grid_normals(field) @ np.asarray(model, np.float64)[:3, :3].T
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    albedo *= (0.7 + 0.3 * _smoothstep(0.55, 0.85, n[..., 1]))[..., None]
    ndl = np.maximum(n @ np.asarray(sun_dir, np.float64), 0.0)
    top, horizon = np.asarray(sky_top, np.float64), 0.35 * np.asarray(sky_horizon, np.float64)
    hemi = (horizon + (top - horizon) * (0.5 * n[..., 1:2] + 0.5)) * float(ambient)
    if sun_visibility is not None:
        ndl = ndl * sun_visibility
    lit = albedo * (np.asarray(sun_color, np.float64) * ndl[..., None] + hemi)
    out = np.ones(h.shape + (4,), np.float32)
    out[..., :3] = lit
    if sun_visibility is not None:
        out[..., 3] = sun_visibility
    return out


def texel_uv(field) -> tuple[tuple[float, float], tuple[float, float]]:
    """(scale, offset): local (x, z) -> texture (u, v) = (x, z) · scale + offset for a texture with one texel per grid
    point of ``field`` (a HeightField), texel centres on the grid points."""
    rows, cols = field.heights.shape
    scale = (1.0 / (field.spacing * cols), 1.0 / (field.spacing * rows))
    return scale, (0.5 / cols - field.origin[0] * scale[0], 0.5 / rows - field.origin[1] * scale[1])


def build_terrain_chunks(field, chunk: int = CHUNK) -> TerrainChunks:
    """Chunked, multi-level mesh of a :class:`~engine.heightfield.HeightField` (see the module docstring)."""
    h = np.asarray(field.heights, np.float64)
    rows, cols = h.shape
    xs = field.origin[0] + np.arange(cols) * field.spacing
    zs = field.origin[1] + np.arange(rows) * field.spacing
    gx, gz = np.meshgrid(xs, zs)
    normals = grid_normals(field)
    grid = np.concatenate([np.stack([gx, h, gz], axis=-1), normals, np.zeros((rows, cols, 1))], axis=-1)
    grid = grid.reshape(-1, VERTEX_FLOATS)

    row_starts = np.arange(0, rows - 1, chunk)
    col_starts = np.arange(0, cols - 1, chunk)
    spans = [(r0, min(r0 + chunk, rows - 1), c0, min(c0 + chunk, cols - 1)) for r0 in row_starts for c0 in col_starts]
    levels = int(np.log2(chunk)) + 1

    # skirt copies of every vertex on an interior chunk line
    on_line = np.zeros((rows, cols), bool)
    on_line[row_starts[1:], :] = True
    on_line[:, col_starts[1:]] = True
    depth = skirt_depths(h, row_starts, col_starts, levels, margin=0.1 * field.spacing)
    skirt_src = np.flatnonzero(on_line.ravel())
    skirt_of = np.full(rows * cols, -1, np.int64)
    skirt_of[skirt_src] = rows * cols + np.arange(skirt_src.size)
    skirts = grid[skirt_src].copy()
    skirts[:, 6] = depth.ravel()[skirt_src]
    vertices = np.concatenate([grid, skirts]).astype(np.float32)

    shape = (levels, len(spans))
    parts, first, count, error, offset = [], np.zeros(shape, np.int64), np.zeros(shape, np.int64), np.zeros(shape), 0
    for level in range(levels):
        step = 1 << level
        for k, (r0, r1, c0, c1) in enumerate(spans):
            rl, cl = _lines(r0, r1, step), _lines(c0, c1, step)
            error[level, k] = level_error(h, rl, cl, r0, c0) if level else 0.0
            tris = [_grid_triangles(rl, cl, cols)]
            if r0 > 0:
                tris.append(_skirt_triangles(r0 * cols + cl, skirt_of))
            if r1 < rows - 1:
                tris.append(_skirt_triangles(r1 * cols + cl, skirt_of))
            if c0 > 0:
                tris.append(_skirt_triangles(rl * cols + c0, skirt_of))
            if c1 < cols - 1:
                tris.append(_skirt_triangles(rl * cols + c1, skirt_of))
            idx = np.concatenate(tris)
            parts.append(idx)
            first[level, k], count[level, k] = offset, idx.size
            offset += idx.size
    box_min = np.array([[xs[c0], h[r0:r1 + 1, c0:c1 + 1].min(), zs[r0]] for r0, r1, c0, c1 in spans])
    box_max = np.array([[xs[c1], h[r0:r1 + 1, c0:c1 + 1].max(), zs[r1]] for r0, r1, c0, c1 in spans])
    error = np.maximum.accumulate(error, axis=0)  # a coarser level never counts as more exact
    scale, offset = texel_uv(field)
    return TerrainChunks(vertices, np.concatenate(parts).astype(np.uint32), first, count, box_min, box_max,
                         error, float(field.spacing), scale, offset)


def _corners(box_min: np.ndarray, box_max: np.ndarray) -> np.ndarray:
    """(chunks, 8, 4) homogeneous corners of axis-aligned boxes."""
    bits = np.array([[(i >> k) & 1 for k in range(3)] for i in range(8)], bool)
    pts = np.where(bits[None], box_max[:, None, :], box_min[:, None, :])
    return np.concatenate([pts, np.ones(pts.shape[:2] + (1,))], axis=-1)


def select_levels(mesh: TerrainChunks, model: np.ndarray, view_proj: np.ndarray, proj: np.ndarray,
                  camera_pos: np.ndarray, view_height: int, ortho: bool, detail_pixels: float) -> np.ndarray:
    """Level per chunk for one view, -1 where the chunk is outside the frustum.

    ``model`` and ``view_proj`` are 4×4 column-vector matrices; ``detail_pixels`` ≤ 0 draws every visible chunk
    at full detail.
    """
    world = _corners(mesh.box_min, mesh.box_max) @ np.asarray(model, np.float64).T  # (chunks, 8, 4)
    clip = world @ np.asarray(view_proj, np.float64).T
    w = clip[..., 3]
    outside = np.zeros(mesh.chunks, bool)
    for axis in range(3):
        outside |= np.all(clip[..., axis] < -w, axis=1) | np.all(clip[..., axis] > w, axis=1)
    if detail_pixels <= 0.0:
        return np.where(outside, -1, 0)
    lo, hi = world[..., :3].min(axis=1), world[..., :3].max(axis=1)
    nearest = np.clip(np.asarray(camera_pos, np.float64), lo, hi)
    distance = np.linalg.norm(nearest - np.asarray(camera_pos, np.float64), axis=1)
    pixels_per_unit = 0.5 * view_height * abs(float(proj[1, 1]))
    if not ortho:
        pixels_per_unit = pixels_per_unit / np.maximum(distance, 1e-3)
    scale_y = float(np.linalg.norm(np.asarray(model, np.float64)[:3, 1]))
    ok = mesh.error * scale_y * pixels_per_unit <= detail_pixels
    level = np.maximum(np.cumprod(ok, axis=0).sum(axis=0) - 1, 0)
    return np.where(outside, -1, level)


def draw_ranges(mesh: TerrainChunks, levels: np.ndarray) -> list[tuple[int, int]]:
    """(first index, index count) draws for the chosen levels, merging ranges that follow each other."""
    draws: list[tuple[int, int]] = []
    visible = np.flatnonzero(levels >= 0)
    order = visible[np.lexsort((visible, levels[visible]))]
    for chunk in order:
        level = levels[chunk]
        first, count = int(mesh.first[level, chunk]), int(mesh.count[level, chunk])
        if draws and draws[-1][0] + draws[-1][1] == first:
            draws[-1] = (draws[-1][0], draws[-1][1] + count)
        else:
            draws.append((first, count))
    return draws
