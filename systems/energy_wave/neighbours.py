"""Neighbour repulsion R (eq. 3.3, seeds/000) with a spatial hash: no all-pairs search.

The points are hashed into a table of cells of size ``radius`` (Müller, Ten Minute Physics #11: integer cell
coordinates hashed with three large primes, counting sort by hash); each query point scans the 27 cells around
its own. Everything is vectorized: the candidate pairs of all queries are generated at once with
``np.repeat``/``cumsum`` and summed per query with ``np.bincount`` (a fixed summation order, so results are
bit-reproducible).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

_PRIMES = np.array([73856093, 19349663, 83492791], dtype=np.int64)
_OFFSETS = np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1], indexing="ij"), axis=-1).reshape(27, 3)
_SAME_POINT = 1e-18
_GOLDEN = 0.6180339887498949  # low-discrepancy phases of the sampled buckets  # squared distance under which a neighbour counts as "at the same position"


def _hash(cells: NDArray[np.int64], table: int) -> NDArray[np.int64]:
    """Cell (ix, iy, iz) -> bucket in [0, table): (ix·p1 xor iy·p2 xor iz·p3) mod table (table a power of 2)."""
    h = (cells[..., 0] * _PRIMES[0]) ^ (cells[..., 1] * _PRIMES[1]) ^ (cells[..., 2] * _PRIMES[2])
    return h & (table - 1)


class SpatialHash:
    """Points sorted by hashed grid cell: ``order`` lists point indices bucket by bucket."""

    def __init__(self, points: F64, cell: float) -> None:
        self.points = points
        self.cell = float(cell)
        self.table = 1 << max(4, int(2 * max(len(points), 1) - 1).bit_length())  # power of 2 >= 2·n
        keys = _hash(np.floor(points / self.cell).astype(np.int64), self.table)
        if self.table <= 1 << 16:
            keys = keys.astype(np.uint16)  # numpy sorts 16-bit keys with a radix (counting) sort
        self.order = np.argsort(keys, kind="stable")
        self.counts = np.bincount(keys, minlength=self.table)
        self.starts = np.cumsum(self.counts) - self.counts

    def candidates(self, query: F64, per_bucket_limit: int = 0
                   ) -> tuple[NDArray[np.int64], NDArray[np.int64], F64 | None]:
        """Candidate pairs (query index, point index, weight or None) from the 27 cells around each query point.

        Buckets reached twice by one query (hash collisions) are scanned once. When ``per_bucket_limit`` > 0, a
        bucket holding more points is sampled with an even stride from a phase that differs per (query, bucket) (a
        golden-ratio sequence, so neighbouring queries do not all see the same subset), each sample weighted
        count/limit: the sum over a crowded bucket stays an unbiased estimate at bounded cost. Weights are None when
        nothing was sampled.
        """
        q = len(query)
        qcells = np.floor(query / self.cell).astype(np.int64)
        keys = _hash(qcells[:, None, :] + _OFFSETS[None, :, :], self.table)  # (q, 27)
        keys.sort(axis=1)
        counts = self.counts[keys]
        counts[:, 1:][keys[:, 1:] == keys[:, :-1]] = 0
        counts, keys = counts.ravel(), keys.ravel()
        sampled = per_bucket_limit > 0 and int(counts.max(initial=0)) > per_bucket_limit
        taken = np.minimum(counts, per_bucket_limit) if sampled else counts
        nonempty = np.flatnonzero(taken)
        taken, counts, keys = taken[nonempty], counts[nonempty], keys[nonempty]
        total = int(taken.sum())
        slot = np.repeat(np.arange(len(nonempty)), taken)
        within = np.arange(total) - np.repeat(np.cumsum(taken) - taken, taken)
        weight = None
        if sampled:
            stride = (counts / taken)[slot]  # 1 unless the bucket was sampled
            phase = (np.arange(len(nonempty)) * _GOLDEN % 1.0)[slot]  # a different subset for every (query, cell)
            within = ((within + phase) * stride).astype(np.int64)
            weight = stride
        point = self.order[np.repeat(self.starts[keys], taken) + within]
        return np.repeat(nonempty // 27, taken), point, weight


def neighbour_repulsion(query: F64, points: F64, radius: float, strength: float,
                        per_bucket_limit: int = 0, point_mask: NDArray[np.bool_] | None = None) -> F64:
    """R (eq. 3.3) for every query point P: r Σ_i (P − Q_i) / |P − Q_i|² over the points Q_i within ``radius``.

    Sign: the thesis prints (Q_i − P), which points towards the neighbours; a repulsion pushes away from them, so
    this returns r Σ (P − Q_i)/|P − Q_i|² (see docs/effects/energy_wave.md). A neighbour at the same position as P
    (including P itself when it is among ``points``) contributes nothing, as the thesis says. Only the points
    where ``point_mask`` is true (all when None) are neighbours.
    """
    query = np.asarray(query, dtype=np.float64)
    out = np.zeros_like(query)
    if len(query) == 0 or len(points) == 0 or strength == 0.0:
        return out
    lo = query.min(axis=0) - radius
    hi = query.max(axis=0) + radius
    px, py, pz = (np.ascontiguousarray(points[:, a]) for a in range(3))
    reach = (px >= lo[0]) & (px <= hi[0]) & (py >= lo[1]) & (py <= hi[1]) & (pz >= lo[2]) & (pz <= hi[2])
    near = np.flatnonzero(reach if point_mask is None else reach & point_mask)  # points that can be within reach
    if len(near) == 0:
        return out
    grid = SpatialHash(points[near], radius)
    qi, pi, weight = grid.candidates(query, per_bucket_limit)
    pi = near[pi]
    qx, qy, qz = (np.ascontiguousarray(query[:, a]) for a in range(3))
    dx = qx[qi] - px[pi]
    dy = qy[qi] - py[pi]
    dz = qz[qi] - pz[pi]
    d2 = dx * dx + dy * dy + dz * dz
    ok = (d2 <= radius * radius) & (d2 > _SAME_POINT)
    w = np.divide(1.0 if weight is None else weight, d2, out=np.zeros_like(d2), where=ok)
    for axis, d in enumerate((dx, dy, dz)):
        out[:, axis] = np.bincount(qi, weights=d * w, minlength=len(query))
    return strength * out
