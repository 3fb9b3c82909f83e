"""Wave propagation on the height field with the added points (seeds/003, section 2.3.2, eq. 2.8–2.12).

With k = c²Δt²/h², every free grid vertex follows the explicit wave equation

    z(t+1) = 2 z(t) − z(t−1) + k (Σ_neighbours w z_nb(t) − (Σ w) z(t))

(the printed eq. 2.8 is garbled; this is its intent). Grid neighbours have weight 1 and count only when they
exist and are water, so an edge vertex has 3, a corner 2 (eq. 2.9, 2.10: reflecting borders) and a vertex next
to a body loses the neighbour inside it (the wave reflects). Added points within radius h of a vertex join its
neighbours with weight r_k / h = 1 − |P N_k| / h (eq. 2.11), and an added point is updated the same way from
the grid vertices and added points within radius h of it (eq. 2.12).

Two deviations from the printed equations, both so that still water stays still and the scheme stays stable:
the centre coefficient uses the sum of the weights (4 + Σ r_k/h) rather than 4 + m (with 4 + m, a flat
surface at any height other than 0 would move: the "small error" the paper mentions), and where the added
neighbours raise that sum D above 4, the local k is lowered to 2 / D (the same Courant bound k·D ≤ 2 that
gives k ≤ 1/2 on the regular grid; a lower local wave speed, as Müller's height-field water clamps it).

Damping (section 2.3.2): after the update every height is multiplied by a factor in [0, 1], taken about the
mean water level so that the volume of water does not leak away.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from engine import exact
from systems.water_surface.geometry import F64, I64, Grid, ranges, sum_of

__all__ = ["courant_k", "dents", "free_degree", "neighbour_sum", "neighbour_table", "propagate"]


def courant_k(wave_speed: float, spacing: float, dt: float) -> float:
    """k = c²Δt²/h² of eq. 2.8."""
    return (wave_speed * dt / spacing) ** 2


def neighbour_sum(field: F64, out: F64 | None = None) -> F64:
    """Sum of the 4 grid neighbours of every vertex; neighbours beyond the border count 0."""
    s = np.zeros_like(field) if out is None else out
    if out is not None:
        s[:, 0] = 0.0
        s[:, 1:] = field[:, :-1]
    else:
        s[:, 1:] += field[:, :-1]
    s[:, :-1] += field[:, 1:]
    s[1:, :] += field[:-1, :]
    s[:-1, :] += field[1:, :]
    return s


def free_degree(nz: int, nx: int) -> F64:
    """Neighbours of each vertex on an open grid: 4 inside, 3 on an edge, 2 at a corner (eq. 2.8–2.10)."""
    return neighbour_sum(np.ones((nz, nx)))


@lru_cache(maxsize=16)
def neighbour_table(nz: int, nx: int) -> I64:
    """(nz·nx, 4) flat indices of each vertex's grid neighbours (+u, −u, +v, −v), −1 beyond the border."""
    flat = np.arange(nz * nx).reshape(nz, nx)
    table = -np.ones((nz, nx, 4), np.int64)
    table[:, :-1, 0] = flat[:, 1:]
    table[:, 1:, 1] = flat[:, :-1]
    table[:-1, :, 2] = flat[1:, :]
    table[1:, :, 3] = flat[:-1, :]
    table = table.reshape(-1, 4)
    table.setflags(write=False)
    return table


def _vertex_groups(touched: I64, slots: I64) -> tuple[I64, I64]:
    """Group the entries of ``touched`` (flat vertex indices, repeats allowed) by vertex without sorting and
    without a grid-sized count: (the distinct vertices, in order of their last entry; each entry's group).

    ``slots`` is a grid-sized int64 work array: every vertex's slot is written before it is read, so its old
    contents never matter."""
    entry = np.arange(len(touched))
    slots[touched] = entry
    last = slots[touched]  # the last entry of each entry's vertex (scatter and gather: no sort)
    own = last == entry
    group = np.add.accumulate(own) - 1
    return touched[own], group[last]


def propagate(z: F64, zp: F64, k: float, coefficient: F64, degree: F64, solid: I64 | None = None,
              pairs: tuple = (), points: F64 | None = None, points_prev: F64 | None = None,
              scratch: F64 | None = None, reuse: bool = False, solid_mask: np.ndarray | None = None,
              slots: I64 | None = None, cut: tuple = ()) -> tuple[F64, F64]:
    """One step of eq. 2.8–2.12: (grid heights at t+1, added-point heights at t+1).

    ``coefficient`` = 2 − k·``degree`` with ``degree`` = :func:`free_degree` (the open grid's neighbour counts);
    ``solid`` holds the flat indices of vertices inside bodies, which their neighbours do not count (their own
    new heights are not meaningful: the caller holds them); ``pairs`` = (grid vertex, point, weight, point,
    point, weight) from ``outline.coupling_pairs``; ``cut`` = (lower, upper) vertices of grid edges a body lies
    across (``outline.cut_edges``), which are not each other's neighbours. The regular update runs on the whole
    grid; the water vertices next to a body or to added points are then updated again with their own neighbours
    (eq. 2.11).
    ``solid_mask`` (the grid's shape, True at ``solid``), ``slots`` (an int64 array of the grid's size) and
    ``scratch`` (the grid's shape) are work arrays the caller may keep between steps; with ``reuse`` the result
    is written over ``zp``, which the caller no longer needs.
    """
    nz, nx = z.shape
    zf, zpf = z.ravel(), zp.ravel()
    index, ds, dd = [], [], []
    if solid is not None and len(solid):  # water neighbours lose the vertices inside bodies (reflection)
        if solid_mask is None:
            solid_mask = np.zeros(z.shape, bool)
            solid_mask.ravel()[solid] = True
        nb = neighbour_table(nz, nx).take(solid, axis=0).ravel()
        water = (nb >= 0) & ~solid_mask.ravel()[nb]
        index.append(nb[water])
        ds.append(-zf[solid].repeat(4)[water])
        dd.append(np.full(len(index[-1]), -1.0))
    if len(cut) and len(cut[0]):  # the two ends of an edge a thin body lies across lose each other
        lo, hi = cut
        index.append(np.stack([lo, hi], axis=1).ravel())
        ds.append(-zf.take(np.stack([hi, lo], axis=1).ravel()))
        dd.append(np.full(2 * len(lo), -1.0))
    has_points = points is not None and len(points) > 0
    if has_points:
        g, p, w, n1, n2, w2 = pairs
        index.append(g)
        ds.append(w * points[p])
        dd.append(w)
    special = None
    if index:  # eq. 2.11 at the water vertices next to bodies or added points
        many = len(index) > 1
        touched = np.concatenate(index) if many else index[0]
        vertices, group = _vertex_groups(touched, np.empty(z.size, np.int64) if slots is None else slots)
        u = len(vertices)
        s_extra = np.bincount(group, np.concatenate(ds) if many else ds[0], u)
        d_extra = np.bincount(group, np.concatenate(dd) if many else dd[0], u)
        around = neighbour_table(nz, nx).take(vertices, axis=0)
        s_t = sum_of(np.where(around >= 0, zf.take(around), 0.0), axis=1) + s_extra
        d_t = degree.ravel()[vertices] + d_extra
        lonely = d_t <= 1e-12
        k_t = np.minimum(k, 2.0 / np.where(lonely, 1.0, d_t))  # k·D ≤ 2: stable with the extra neighbours
        z_t = zf[vertices]
        special = np.where(lonely, z_t, 2.0 * z_t - zpf[vertices] + k_t * (s_t - d_t * z_t))
    # eq. 2.8: z(t+1) = (2 − n·k)·z − z(t−1) + Σ_neighbours k·z_nb, in seven contiguous passes over the grid
    s = scratch if scratch is not None and scratch.flags.c_contiguous else np.empty(z.shape)
    new = zp if reuse and zp.flags.c_contiguous else np.empty(z.shape)
    np.multiply(coefficient, z, out=s)
    np.subtract(s, zp, out=new)
    np.multiply(z, k, out=s)
    flat, sf = new.ravel(), s.ravel()
    # the ±u neighbours as shifts of the flat arrays (a strided 2-D slice is ~3x slower); the shift carries a
    # row's end over to the next row's start, so the border column it lands on is put back as it was
    border = new[:, 0].copy()
    flat[1:] += sf[:-1]
    new[:, 0] = border
    border = new[:, -1].copy()
    flat[:-1] += sf[1:]
    new[:, -1] = border
    new[1:, :] += s[:-1, :]
    new[:-1, :] += s[1:, :]
    if special is not None:
        new.ravel()[vertices] = special
    if not has_points:
        return new, np.zeros(0)
    m = len(points)  # eq. 2.12 at the added points
    s_n = np.bincount(p, w * zf[g], m) + np.bincount(n1, w2 * points[n2], m)
    d_n = np.bincount(p, w, m) + np.bincount(n1, w2, m)
    isolated = d_n <= 0.0
    k_n = np.minimum(k, 2.0 / np.where(isolated, 1.0, d_n))
    new_points = np.where(isolated, points, 2.0 * points - points_prev + k_n * (s_n - d_n * points))
    return new, new_points


def dents(grid: Grid, centres_uv: F64, heights: F64, radius: float) -> tuple[I64, F64]:
    """Gaussian dents −H·exp(−r²/R²) at ``centres_uv`` (grid units): (flat vertex index, height change), summed."""
    if len(centres_uv) == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    r = radius / grid.h
    reach = int(np.ceil(2.0 * r))
    # each drop's 2·reach square of vertices, clipped to the grid first (a radius of many cells on a small grid
    # would otherwise list millions of vertices to throw away), row by row in the same order as unclipped
    lo = np.floor(centres_uv).astype(np.int64) - reach + 1
    hi = lo + 2 * reach
    lo_c, hi_c = np.maximum(lo, 0), np.minimum(hi, (grid.nx, grid.nz))
    width = np.maximum(hi_c - lo_c, 0)  # (D, 2) columns, rows
    drop, offset = ranges(np.zeros(len(centres_uv), np.int64), width[:, 0] * width[:, 1])
    dv, du = np.divmod(offset, np.maximum(width[drop, 0], 1))
    i, j = lo_c[drop, 0] + du, lo_c[drop, 1] + dv
    r2 = (i - centres_uv[drop, 0]) ** 2 + (j - centres_uv[drop, 1]) ** 2
    change = -heights[drop] * exact.exp(-r2 / (r * r))
    flat = j * grid.nx + i
    touched, inverse = np.unique(flat, return_inverse=True)
    return touched, np.bincount(inverse, change, len(touched))
