"""Neighbour repulsion R (eq. 3.3, seeds/000) with a spatial hash: no all-pairs search.

The points are hashed into a table of cells of size ``radius`` (Müller, Ten Minute Physics #11: integer cell
coordinates hashed with three large primes, counting sort by hash); each query point scans the 27 cells around
its own, skipping the cells whose nearest point is farther than the radius (exact: they hold no neighbour).
Crowded buckets are sampled with weights (see :func:`.kernels.repulsion_sums`) so the cost per query is bounded.
Several independent groups (one per emitter: its points repel only its own queries) are computed at once, their
tables laid end to end, with exactly the result each group would get alone. The loops over points, queries and
buckets are compiled kernels (:mod:`.kernels`); the sums run in a fixed order, so results are bit-reproducible.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .kernels import GOLDEN, PRIME_X, PRIME_Y, PRIME_Z, hash_points, repulsion_sums

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

_PRIMES = np.array([PRIME_X, PRIME_Y, PRIME_Z], dtype=np.int64)
_GOLDEN = GOLDEN


def _hash(cells: I64, table: int | I64) -> I64:
    """Cell (ix, iy, iz) -> bucket in [0, table): (ix·p1 xor iy·p2 xor iz·p3) mod table (table a power of 2);
    the kernels' hash, for tests and tools."""
    h = cells[..., 0] * _PRIMES[0]
    h ^= cells[..., 1] * _PRIMES[1]
    h ^= cells[..., 2] * _PRIMES[2]
    h &= table - 1
    return h


def _table_size(points: int) -> int:
    """Hash-table size of ``points`` points: the power of 2 >= 2·points (at least 16)."""
    return 1 << max(4, int(2 * max(points, 1) - 1).bit_length())


def in_reach(points: F64, query: F64, radius: float, mask: NDArray[np.bool_] | None = None) -> I64:
    """Indices of the ``points`` (where ``mask``) inside the queries' bounding box grown by ``radius``."""
    return in_box(points, query.min(axis=0) - radius, query.max(axis=0) + radius, mask)


def in_box(points: F64, lo: F64, hi: F64, mask: NDArray[np.bool_] | None = None) -> I64:
    """Indices of the ``points`` (where ``mask``) with lo <= p <= hi on every axis."""
    column = points[:, 0]
    inside = column >= lo[0]
    inside &= column <= hi[0]
    if mask is not None:
        inside &= mask
    found = np.flatnonzero(inside)  # the first axis over every point, the others over its survivors only
    for axis in (1, 2):
        column = points[found, axis]
        found = found[(column >= lo[axis]) & (column <= hi[axis])]
    return found


class _Workspace:
    """Work arrays reused by every call: allocating arrays as large as the neighbour set anew each step cost a page
    fault per 4 KiB on small VMs (the allocator hands freed memory back). Never state: each call writes them
    before reading them, and what a call returns is copied out of them (so :func:`grouped_repulsion` is not
    re-entrant)."""

    def __init__(self) -> None:
        self.tables: dict[str, NDArray] = {}

    def table(self, name: str, size: int, dtype: type = np.float64) -> NDArray:
        """A reused 1-d array ``name`` of ``size`` elements."""
        array = self.tables.get(name)
        if array is None or len(array) < size:
            array = self.tables[name] = np.empty(max(size, 4096), dtype=dtype)
        return array[:size]


_WORK = _Workspace()


def neighbour_repulsion(query: F64, points: F64, radius: float, strength: float,
                        per_bucket_limit: int = 0, point_mask: NDArray[np.bool_] | None = None) -> F64:
    """R (eq. 3.3) for every query point P: r Σ_i (P − Q_i) / |P − Q_i|² over the points Q_i within ``radius``.

    Sign: the thesis prints (Q_i − P), which points towards the neighbours; a repulsion pushes away from them, so
    this returns r Σ (P − Q_i)/|P − Q_i|² (see docs/effects/energy_wave.md). A neighbour at the same position as P
    (including P itself when it is among ``points``) contributes nothing, as the thesis says. Only the points
    where ``point_mask`` is true (all when None) are neighbours; ``per_bucket_limit`` > 0 samples crowded cells
    (see :meth:`SpatialHash.buckets`).
    """
    query = np.asarray(query, dtype=np.float64)
    if len(query) == 0 or len(points) == 0:
        return np.zeros_like(query)
    near = in_reach(points, query, radius, point_mask)  # points that can be within reach
    return grouped_repulsion([(query, points[near], radius, strength)], per_bucket_limit)[0]


def grouped_repulsion(groups: list[tuple[F64, F64, float, float]], per_bucket_limit: int = 0) -> list[F64]:
    """:func:`neighbour_repulsion` of independent groups (query, points, radius, strength) at once, each group's
    ``points`` already restricted to :func:`in_reach` of its queries (the hash table is sized by them): the
    same results as one group at a time. Two compiled passes (:mod:`.kernels`): hash every group's points, then
    sum every query's neighbours."""
    out = [np.zeros((len(q), 3)) for q, _, _, _ in groups]
    live = [g for g, (q, p, _, strength) in enumerate(groups) if len(q) and len(p) and strength != 0.0]
    if not live:
        return out
    points = np.concatenate([groups[g][1] for g in live], dtype=np.float64)
    query = np.concatenate([groups[g][0] for g in live], dtype=np.float64)
    point_first = np.cumsum([0] + [len(groups[g][1]) for g in live])
    query_first = np.cumsum([0] + [len(groups[g][0]) for g in live])
    cells = np.array([groups[g][2] for g in live], dtype=np.float64)
    strength = np.array([groups[g][3] for g in live], dtype=np.float64)
    tables = np.array([_table_size(len(groups[g][1])) for g in live], dtype=np.int64)
    offsets = np.cumsum(tables) - tables
    buckets = int(tables.sum())
    counts = _WORK.table("counts", buckets, np.int64)
    starts = _WORK.table("starts", buckets, np.int64)
    xyz = _WORK.table("xyz", 3 * len(points)).reshape(-1, 3)
    hash_points(points, point_first, cells, offsets, tables, _WORK.table("keys", len(points), np.int64), counts,
                starts, _WORK.table("fill", buckets, np.int64), xyz)
    total = np.empty((len(query), 3))
    repulsion_sums(query, query_first, cells, offsets, tables, strength, int(per_bucket_limit), counts, starts, xyz,
                   total)
    for i, g in enumerate(live):  # loop over groups
        out[g] = total[query_first[i]: query_first[i + 1]]
    return out
