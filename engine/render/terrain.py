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
  (de Boer 2000); its quads must also stay within a multiple of ``detail_pixels`` on screen, so that the
  per-vertex lighting keeps its detail: ``QUAD_PIXELS_PERSPECTIVE`` (8) in perspective views, and
  ``QUAD_PIXELS_ORTHOGRAPHIC`` (2) in orthographic ones, which look down on the ground so that a height
  error moves no pixel and shading detail is all that a coarser level loses;
* cracks between neighbours at different levels are hidden by skirts: along every interior chunk edge a strip
  hangs from the edge vertices to copies lowered by the field's largest chunk height range, drawn with the
  edge's colour (the vertex shader lowers a skirt vertex after shading it).

On a software rasteriser the terrain is bound by vertex work (per-vertex lighting, triangle setup), so culling
and coarser levels cut its cost nearly in proportion to the triangles skipped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CHUNK = 16  # quads per chunk side; a power of two so that levels 0..log2(CHUNK) all fit exactly
QUAD_PIXELS_PERSPECTIVE = 8.0  # on-screen quad size allowed per pixel of tolerated error, perspective views
QUAD_PIXELS_ORTHOGRAPHIC = 2.0  # the same for orthographic (top) views, where height error moves nothing
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


def _skirt_triangles(edge: np.ndarray, skirt_of: np.ndarray) -> np.ndarray:
    """A strip of two triangles per edge segment, from the edge vertices down to their skirt copies."""
    a, b = edge[:-1], edge[1:]
    sa, sb = skirt_of[a], skirt_of[b]
    return np.stack([a, b, sa, b, sb, sa], axis=-1).ravel()


def build_terrain_chunks(field, chunk: int = CHUNK) -> TerrainChunks:
    """Chunked, multi-level mesh of a :class:`~engine.heightfield.HeightField` (see the module docstring)."""
    h = np.asarray(field.heights, np.float64)
    rows, cols = h.shape
    xs = field.origin[0] + np.arange(cols) * field.spacing
    zs = field.origin[1] + np.arange(rows) * field.spacing
    gx, gz = np.meshgrid(xs, zs)
    dz, dx = np.gradient(h, field.spacing)
    normals = np.stack([-dx, np.ones_like(h), -dz], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
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
    ranges = [float(np.ptp(h[r0:r1 + 1, c0:c1 + 1])) for r0, r1, c0, c1 in spans]
    depth = max(ranges) + field.spacing
    skirt_src = np.flatnonzero(on_line.ravel())
    skirt_of = np.full(rows * cols, -1, np.int64)
    skirt_of[skirt_src] = rows * cols + np.arange(skirt_src.size)
    skirts = grid[skirt_src].copy()
    skirts[:, 6] = depth
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
    return TerrainChunks(vertices, np.concatenate(parts).astype(np.uint32), first, count, box_min, box_max,
                         error, float(field.spacing))


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
    scale_xz = float(np.linalg.norm(np.asarray(model, np.float64)[:3, 0]))
    pixels_per_unit = 0.5 * view_height * abs(float(proj[1, 1]))
    if not ortho:
        pixels_per_unit = pixels_per_unit / np.maximum(distance, 1e-3)
    quad_pixels = mesh.quad_size * scale_xz * pixels_per_unit * (1 << np.arange(mesh.levels))[:, None]
    scale_y = float(np.linalg.norm(np.asarray(model, np.float64)[:3, 1]))
    error_pixels = mesh.error * scale_y * pixels_per_unit
    quad_limit = (QUAD_PIXELS_ORTHOGRAPHIC if ortho else QUAD_PIXELS_PERSPECTIVE) * detail_pixels
    ok = (error_pixels <= detail_pixels) & (quad_pixels <= quad_limit)
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
