"""Compiled kernels (``engine.jit.kernel``) for one frame's plan of a field (seeds/001, sections 3, 5 and 6).

The numpy functions of ``culling.py`` and ``lod.py`` are the readable statement of the method; a frame plan made
of them costs about 1.3 ms for 1600 cells, nearly all of it numpy's per-call overhead (some 150 calls on arrays of
a few hundred elements).  These kernels do the same arithmetic in the same order in three calls:

- :func:`cell_levels`: per-cell culling (section 3) and the level of eq. 1 / table 2, level 5 past the band;
- :func:`plants_to_draw`: the geometric cells nearest first, the plants of theirs that the frustum can see, the
  near levels' plants nearest first, and the real primitives of table 4;
- :func:`orient_impostors`: the level-4 rectangles' 15° / 30° rules (section 5) and their draw order.

The tests compare every kernel's results with the numpy functions' (``plan_frame(..., compiled=False)``).
Transcendental functions are float64, as everywhere; no fastmath. Angles come from engine.exact's ``atan2`` and
``asin``, as in the numpy functions, so both give the same bits on every CPU.
"""

from __future__ import annotations

import math

import numpy as np

from engine.exact import asin_scalar, atan2_scalar
from engine.jit import kernel

TWO_PI = 2.0 * np.pi
N_VIEWS = 12  # lod.N_VIEWS (cached images per cell, every 30°)


@kernel
def _wrap(a):
    """lod.wrap_angle: ``a`` wrapped into [-π, π) (numpy's floored remainder, as Python's ``%``)."""
    return (a + np.pi) % TWO_PI - np.pi


@kernel
def cell_levels(centres, lod_points, eye, fwd_xz, theta, cell_radius, near_distance, viewer, pixel_scale,
                thresholds, level_cap, band_normals, merge_distance, use_band):
    """(C,) int64 level of every cell, -1 where culled: culling.cull_cells then lod.select_levels.

    Section 3 (culling): a cell is kept while its centre's azimuth is within the half view angle ``theta`` widened
    by the cell's angular radius, or within 2θ when nearer than ``near_distance``; the ``viewer`` cell always.
    Eq. 1: P = W L / (2 D tan θ), here ``pixel_scale`` = W L and the division by 2 D tan θ done as numpy does it;
    table 2: the level is the number of ``thresholds`` above P, capped at ``level_cap`` (min(max_level, 4)).
    Section 6: with ``use_band``, cells whose 12-gon distance from the viewer's cell centre is at least
    ``merge_distance`` are level 5.  ``pixel_scale`` is (W L, tan θ) packed as a 2-tuple.
    """
    n = centres.shape[0]
    out = np.empty(n, dtype=np.int64)
    fwd_azimuth = atan2_scalar(fwd_xz[1], fwd_xz[0])
    width_length, tan_half = pixel_scale
    vx, vz = centres[viewer, 0], centres[viewer, 2]
    for c in range(n):
        rx = centres[c, 0] - eye[0]
        rz = centres[c, 2] - eye[2]
        dist = math.sqrt(rx * rx + rz * rz)
        angle = abs(_wrap(atan2_scalar(rz, rx) - fwd_azimuth))
        ratio = cell_radius / max(dist, 1e-9)
        ratio = min(max(ratio, 0.0), 1.0)
        keep = angle <= theta + asin_scalar(ratio)
        if not keep:
            keep = dist <= near_distance and angle <= 2.0 * theta
        if not keep and c != viewer:
            out[c] = -1
            continue
        px = lod_points[c, 0] - eye[0]
        py = lod_points[c, 1] - eye[1]
        pz = lod_points[c, 2] - eye[2]
        d = max(math.sqrt(px * px + py * py + pz * pz), 1e-9)
        pixels = width_length / (2.0 * d * tan_half)
        level = 0
        for t in thresholds:
            if t > pixels:
                level += 1
        level = min(level, level_cap)
        if use_band:
            bx = centres[c, 0] - vx
            bz = centres[c, 2] - vz
            far = -np.inf
            for k in range(band_normals.shape[0]):
                far = max(far, bx * band_normals[k, 0] + bz * band_normals[k, 1])
            if far >= merge_distance:
                level = 5
        out[c] = level
    return out


@kernel
def _stable_order(keys):
    """Indices sorting ``keys`` ascending, equal keys in their given order (numpy's stable argsort)."""
    return np.argsort(keys, kind="mergesort")


@kernel
def plants_to_draw(levels, centres, eye, plants_per_cell, plant_position, cell_centre, cell_radius,
                   plant_offset, plant_radius, planes, use_planes, near_sorted, plant_variant, real_primitives):
    """(cells, cell counts (4,), plants, plant counts (4,), primitives (4,)): frame._near_first,
    culling.visible_plants and the near levels' sort of frame._plants_to_draw in one pass.

    The cells at geometric levels 0-3 are taken level by level, nearest first (squared distance of their centre,
    ties in index order); a cell's plants follow in order, those of a cell straddling a frustum side (``planes``,
    (4, 4) inward side planes) only when their bounding sphere touches the frustum.  The plants of levels below
    ``near_sorted`` are then ordered nearest first (stable).  ``real_primitives`` (4, V) are the real primitives
    of each level's plant variants (table 4).
    """
    n = plants_per_cell
    cells_at = np.zeros(5, dtype=np.int64)
    for c in range(levels.shape[0]):
        if 0 <= levels[c] <= 3:
            cells_at[levels[c] + 1] += 1
    for k in range(4):
        cells_at[k + 1] += cells_at[k]
    geometric = np.empty(cells_at[4], dtype=np.int64)
    fill = cells_at[:4].copy()
    for c in range(levels.shape[0]):
        if 0 <= levels[c] <= 3:
            geometric[fill[levels[c]]] = c
            fill[levels[c]] += 1
    ordered = np.empty_like(geometric)
    out = np.empty(geometric.shape[0] * n, dtype=np.int32)
    counts = np.zeros(4, dtype=np.int64)
    primitives = np.zeros(4, dtype=np.int64)
    m = 0
    for k in range(4):
        group = geometric[cells_at[k]:cells_at[k + 1]]
        dist2 = np.empty(group.shape[0])
        for i in range(group.shape[0]):
            rx = centres[group[i], 0] - eye[0]
            ry = centres[group[i], 1] - eye[1]
            rz = centres[group[i], 2] - eye[2]
            dist2[i] = rx * rx + ry * ry + rz * rz
        start = m
        order = _stable_order(dist2)
        for i in range(group.shape[0]):
            c = group[order[i]]
            ordered[cells_at[k] + i] = c
            inside = True
            if use_planes:
                for p in range(4):
                    s = (cell_centre[c, 0] * planes[p, 0] + cell_centre[c, 1] * planes[p, 1]
                         + cell_centre[c, 2] * planes[p, 2]) + planes[p, 3]
                    if s < cell_radius[c]:
                        inside = False
            for j in range(c * n, c * n + n):
                if not inside:
                    x = plant_position[j, 0] + plant_offset[0]
                    y = plant_position[j, 1] + plant_offset[1]
                    z = plant_position[j, 2] + plant_offset[2]
                    touching = True
                    for p in range(4):
                        s = (x * planes[p, 0] + y * planes[p, 1] + z * planes[p, 2]) + planes[p, 3]
                        if s < -plant_radius:
                            touching = False
                    if not touching:
                        continue
                out[m] = j
                m += 1
        if k < near_sorted and m - start > 1:
            dist2 = np.empty(m - start)
            for i in range(m - start):
                j = out[start + i]
                rx = plant_position[j, 0] - eye[0]
                ry = plant_position[j, 1] - eye[1]
                rz = plant_position[j, 2] - eye[2]
                dist2[i] = rx * rx + ry * ry + rz * rz
            out[start:m] = out[start:m][_stable_order(dist2)]
        counts[k] = m - start
        for i in range(start, m):
            primitives[k] += real_primitives[k, plant_variant[out[i]]]
    return ordered, cells_at[1:] - cells_at[:4], out[:m], counts, primitives


@kernel
def orient_impostors(levels, centres, eye, face, image, face_step, image_step, cell_turn):
    """Section 5, the rectangles of the cells at level 4: lod.ImpostorOrientation.update (turn to face the eye
    once its azimuth moved ``face_step`` (15°), swap the image for the nearest of the 12 once ``image_step``
    (30°) away; ``face`` and ``image`` updated in place, NaN off level 4), then the level-4 cells nearest first
    (stable) with the azimuth each faces and the cached view of its layout (lod.ImpostorOrientation.local_view).

    Returns (cells, faces, views, turns, swaps).
    """
    step = TWO_PI / N_VIEWS
    turns = 0
    swaps = 0
    active = 0
    for c in range(levels.shape[0]):
        if levels[c] != 4:
            face[c] = np.nan
            image[c] = np.nan
            continue
        active += 1
        angle = atan2_scalar(-(centres[c, 2] - eye[2]), -(centres[c, 0] - eye[0])) % TWO_PI
        nearest = (np.rint(angle / step) % N_VIEWS) * step
        if np.isnan(face[c]):
            face[c] = angle
            image[c] = nearest
            continue
        if abs(_wrap(angle - face[c])) >= face_step - 1e-12:
            face[c] = angle
            turns += 1
        if abs(_wrap(angle - image[c])) >= image_step - 1e-12:
            image[c] = nearest
            swaps += 1
    cells = np.empty(active, dtype=np.int64)
    dist2 = np.empty(active)
    i = 0
    for c in range(levels.shape[0]):
        if levels[c] == 4:
            cells[i] = c
            rx = centres[c, 0] - eye[0]
            ry = centres[c, 1] - eye[1]
            rz = centres[c, 2] - eye[2]
            dist2[i] = rx * rx + ry * ry + rz * rz
            i += 1
    cells = cells[_stable_order(dist2)]
    faces = np.empty(active)
    views = np.empty(active, dtype=np.int64)
    for i in range(active):
        c = cells[i]
        faces[i] = face[c]
        views[i] = (np.int64(np.rint(image[c] / step)) - 3 * cell_turn[c]) % N_VIEWS
    return cells, faces, views, turns, swaps
