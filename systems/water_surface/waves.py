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

import numpy as np

from systems.water_surface.geometry import F64, I64, Grid, ranges

__all__ = ["courant_k", "dents", "free_degree", "neighbour_sum", "propagate"]


def courant_k(wave_speed: float, spacing: float, dt: float) -> float:
    """k = c²Δt²/h² of eq. 2.8."""
    return (wave_speed * dt / spacing) ** 2


def neighbour_sum(field: F64) -> F64:
    """Sum of the 4 grid neighbours of every vertex; neighbours beyond the border count 0."""
    s = np.zeros_like(field)
    s[:, 1:] += field[:, :-1]
    s[:, :-1] += field[:, 1:]
    s[1:, :] += field[:-1, :]
    s[:-1, :] += field[1:, :]
    return s


def free_degree(nz: int, nx: int) -> F64:
    """Neighbours of each vertex on an open grid: 4 inside, 3 on an edge, 2 at a corner (eq. 2.8–2.10)."""
    return neighbour_sum(np.ones((nz, nx)))


def propagate(z: F64, zp: F64, k: float, degree: F64, fluid: np.ndarray | None = None,
              pairs: tuple = (), points: F64 | None = None, points_prev: F64 | None = None
              ) -> tuple[F64, F64]:
    """One step of eq. 2.8–2.12: (grid heights at t+1, added-point heights at t+1).

    ``fluid`` (bool, nz × nx) marks vertices that are water (None: all); ``degree`` is :func:`free_degree` (used
    when every vertex is water). ``pairs`` = (grid vertex, point, weight, point, point, weight) from
    ``outline.coupling_pairs``.
    """
    if fluid is None:
        s = neighbour_sum(z)
        d = degree
    else:
        f = fluid.astype(np.float64)
        s = neighbour_sum(z * f)
        d = neighbour_sum(f)
    lap = s - d * z
    new = 2.0 * z - zp + k * lap
    if points is None or len(points) == 0:
        return new, np.zeros(0)
    g, p, w, n1, n2, w2 = pairs
    m = len(points)
    zf, zpf, newf = z.ravel(), zp.ravel(), new.ravel()
    if len(g):  # eq. 2.11 at the grid vertices with added neighbours
        touched, inverse = np.unique(g, return_inverse=True)
        s_t = s.ravel()[touched] + np.bincount(inverse, w * points[p], len(touched))
        d_t = d.ravel()[touched] + np.bincount(inverse, w, len(touched))
        k_t = np.minimum(k, 2.0 / d_t)
        z_t = zf[touched]
        newf[touched] = 2.0 * z_t - zpf[touched] + k_t * (s_t - d_t * z_t)
    # eq. 2.12 at the added points
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
    lo = np.floor(centres_uv).astype(np.int64) - reach + 1
    side = 2 * reach
    drop, offset = ranges(np.zeros(len(centres_uv), np.int64), np.full(len(centres_uv), side * side))
    dv, du = np.divmod(offset, side)
    i, j = lo[drop, 0] + du, lo[drop, 1] + dv
    ok = (i >= 0) & (i < grid.nx) & (j >= 0) & (j < grid.nz)
    drop, i, j = drop[ok], i[ok], j[ok]
    r2 = (i - centres_uv[drop, 0]) ** 2 + (j - centres_uv[drop, 1]) ** 2
    change = -heights[drop] * np.exp(-r2 / (r * r))
    flat = j * grid.nx + i
    touched, inverse = np.unique(flat, return_inverse=True)
    return touched, np.bincount(inverse, change, len(touched))
