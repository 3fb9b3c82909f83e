"""Neighbour repulsion R (eq. 3.3, seeds/000) with a spatial hash: no all-pairs search.

The points are hashed into a table of cells of size ``radius`` (Müller, Ten Minute Physics #11: integer cell
coordinates hashed with three large primes, counting sort by hash); each query point scans the 27 cells around
its own, skipping the cells whose nearest point is farther than the radius (about a quarter of them: exact, they
hold no neighbour). Crowded buckets are sampled with weights (see :meth:`SpatialHash.buckets`) so the cost per
query is bounded. Several independent groups (one per emitter: its points repel only its own queries) are computed at
once, their tables laid end to end, with exactly the result each group would get alone. Everything is vectorized
over the (query, bucket) pairs: the samples are laid out (sample, pair) in blocks of a few thousand (sampled
buckets, whose slots follow a stride, apart from fully scanned ones, whose slots are consecutive), computed in
reused work arrays (no per-step allocation) and summed in a fixed order, so results are bit-reproducible.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

_PRIMES = np.array([73856093, 19349663, 83492791], dtype=np.int64)
_STEPS = np.array([-1, 0, 1], dtype=np.int64)  # cell offsets along each axis: 3 x 3 x 3 neighbouring cells
_OFFSETS = np.arange(27, dtype=np.int64)  # the 27 cells around a cell, 9·ix + 3·iy + iz
_BITS = np.left_shift(1, _OFFSETS)  # their bits in a mask
_SAME_POINT = 1e-18  # squared distance under which a neighbour counts as "at the same position"
_GOLDEN = 0.6180339887498949  # low-discrepancy phases of the sampled buckets
_BLOCK_SLOTS = 16384  # (sample, pair) slots per block: 64 KiB per float64 work array, the block stays in L2


def _hash(cells: I64, table: int | I64) -> I64:
    """Cell (ix, iy, iz) -> bucket in [0, table): (ix·p1 xor iy·p2 xor iz·p3) mod table (table a power of 2)."""
    h = cells[..., 0] * _PRIMES[0]
    h ^= cells[..., 1] * _PRIMES[1]
    h ^= cells[..., 2] * _PRIMES[2]
    h &= table - 1
    return h


def _hash_around(cells: I64, mask: I64) -> I64:
    """Buckets (q, 27) of the 3 x 3 x 3 cells around each cell (q, 3): the hash of :func:`_hash`, each axis's
    three products computed once; ``mask`` (q,) is each query's table size - 1. Built (27, q), the long axis
    inner, then transposed."""
    hx, hy, hz = ((cells[:, axis] + _STEPS[:, None]) * _PRIMES[axis] for axis in range(3))  # (3, q) each
    h = hx[:, None, None, :] ^ hy[None, :, None, :] ^ hz[None, None, :, :]
    h = h.reshape(27, len(cells))
    h &= mask
    return h.T.copy()


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
    """Work arrays reused by every call: allocating arrays this large anew each step cost a page fault per 4 KiB
    on small VMs (the allocator hands freed memory back). Never state: each call writes them before reading them,
    and what a call returns is copied out of them (so :func:`grouped_repulsion` is not re-entrant)."""

    def __init__(self) -> None:
        self.size = 0
        self.tables: dict[str, NDArray] = {}

    def table(self, name: str, size: int, dtype: type = np.float64) -> NDArray:
        """A reused 1-d array ``name`` of ``size`` elements."""
        array = self.tables.get(name)
        if array is None or len(array) < size:
            array = self.tables[name] = np.empty(max(size, 4096), dtype=dtype)
        return array[:size]

    def arrays(self, samples: int, pairs: int) -> tuple:
        """Views (index, deltas (3, ...), d2, w, ok, mask), each (samples, pairs)."""
        shape, size = (samples, pairs), samples * pairs
        if size > self.size:
            self.size = max(size, _BLOCK_SLOTS)
            self.index = np.empty(self.size, dtype=np.int64)
            self.floats = np.empty((5, self.size))
            self.flags = np.empty((2, self.size), dtype=bool)
        floats = self.floats[:, :size]
        return (self.index[:size].reshape(shape), floats[0:3].reshape((3, *shape)), floats[3].reshape(shape),
                floats[4].reshape(shape), self.flags[0, :size].reshape(shape), self.flags[1, :size].reshape(shape))


_WORK = _Workspace()
_K = np.arange(1 << 16, dtype=np.int64)[:, None]  # sample numbers k (a column)
_KF = _K.astype(np.float64)


class SpatialHash:
    """The points of several groups hashed into per-group tables laid end to end (group g's bucket b is global
    bucket ``offset[g] + b``): bucket B holds sorted slots ``starts[B] .. starts[B] + counts[B]``, ``xyz`` (3, n)
    the point coordinates in that order. A group's table and order are those it would have alone. The arrays are
    work arrays: valid until the next SpatialHash is built."""

    def __init__(self, points: list[F64], cells: F64) -> None:
        sizes = [len(p) for p in points]
        self.cells = np.asarray(cells, dtype=np.float64)
        self.tables = np.array([_table_size(n) for n in sizes], dtype=np.int64)
        self.offsets = np.cumsum(self.tables) - self.tables
        self.counts = _WORK.table("counts", int(self.tables.sum()), np.int64)
        self.xyz = _WORK.table("xyz", 3 * sum(sizes)).reshape(3, -1)
        base = 0
        for g, group in enumerate(points):  # loop over groups (emitters): each sorted on its own, in cache
            scaled = np.divide(group, self.cells[g])
            keys = _hash(np.floor(scaled, out=scaled).astype(np.int64), int(self.tables[g]))
            # numpy sorts 16-bit keys with a radix (counting) sort
            order = (keys.astype(np.uint16) if self.tables[g] <= 1 << 16 else keys).argsort(kind="stable")
            table = slice(int(self.offsets[g]), int(self.offsets[g] + self.tables[g]))
            self.counts[table] = np.bincount(keys, minlength=int(self.tables[g]))
            self.xyz[:, base: base + len(group)] = np.take(group, order, axis=0).T  # rows at once, then transposed
            base += len(group)
        self.starts = np.cumsum(self.counts, out=_WORK.table("starts", len(self.counts), np.int64))
        self.starts -= self.counts

    def buckets(self, query: F64, sizes: list[int], per_bucket_limit: int = 0) -> _Buckets:
        """The non-empty buckets among the 27 cells around each query (``query`` holds the groups' queries one
        group after the other, ``sizes[g]`` of group g), as flat (query, bucket) pairs, query-major and by bucket
        within a query.

        A group's crowded buckets are sampled when ``per_bucket_limit`` > 0 and one of its queries reaches a
        bucket of more points: ``per_bucket_limit`` samples at an even stride count/limit from a phase (a
        golden-ratio sequence over the group's (query, bucket) pairs, so neighbouring queries do not all see the
        same subset), each weighted by the stride, so the sum over the bucket stays an unbiased estimate at
        bounded cost. Otherwise every point is taken with weight 1. A bucket reached twice by one query (a hash
        collision) is scanned once.

        Queries in the same cell reach the same buckets: the buckets are found once per distinct (group, cell)
        and each query takes its cell's list, less the buckets that only cells beyond its reach map to.
        """
        groups = np.repeat(np.arange(len(sizes)), sizes)  # group of each query
        scaled = query / self.cells[groups, None]
        cells = np.floor(scaled)
        near_bits = _near_bits(scaled - cells, np.abs(scaled).max(axis=1))
        cell, group, cell_of = _distinct_cells(cells.astype(np.int64), groups)
        # Each distinct cell's buckets, ascending, each once: (bucket << 5 | offset) sorted along the 27 offsets;
        # a bucket that several offsets map to keeps the bit mask of all of them.
        keys = _hash_around(cell, (self.tables - 1)[group])
        keys <<= 5
        keys |= _OFFSETS
        keys.sort(axis=1)
        bits = np.left_shift(1, keys & 31)
        keys >>= 5
        keys += self.offsets[group, None]
        first = np.ones(keys.shape, dtype=bool)
        np.not_equal(keys[:, 1:], keys[:, :-1], out=first[:, 1:])
        first = np.flatnonzero(first)
        mask = np.bitwise_or.reduceat(bits.ravel(), first)  # offsets of each distinct (cell, bucket)
        keys = keys.ravel()[first]
        owner_cell = first // 27
        counts = self.counts[keys]
        if per_bucket_limit > 0:  # sampled groups: some query of theirs reaches a crowded bucket
            group_first = np.searchsorted(group[owner_cell], np.arange(len(sizes)))
            sampled = np.maximum.reduceat(counts, group_first) > per_bucket_limit
            taken = np.minimum(counts, np.where(sampled, per_bucket_limit, np.iinfo(np.int64).max)[group[owner_cell]])
        else:
            taken = counts
        full = np.flatnonzero(taken)
        keys, counts, taken, mask, owner_cell = keys[full], counts[full], taken[full], mask[full], owner_cell[full]
        per_cell = np.bincount(owner_cell, minlength=len(cell))
        start, stride = self.starts[keys], counts / taken
        # Every query gets its cell's list: pairs (query, entry), query-major.
        reached = per_cell[cell_of]
        query_first = np.cumsum(reached) - reached  # each query's first pair
        entry = np.repeat((np.cumsum(per_cell) - per_cell)[cell_of] - query_first, reached)
        entry += np.arange(len(entry))
        # Pairs whose bucket is reached only through cells beyond reach hold no point within reach: dropped
        # after the phases and the sampling were decided, so the result is that of scanning them.
        near = mask[entry]
        near &= np.repeat(near_bits, reached)
        near = near.nonzero()[0]
        entry = entry[near]
        owner = np.repeat(np.arange(len(query)), reached)[near]
        # Phase of a sampled pair: its serial number within its group (among all its pairs) times the golden
        # ratio, mod 1.
        first_query = np.cumsum(sizes) - sizes
        group_first = query_first[first_query]
        bounds = np.searchsorted(near, np.append(group_first, query_first[-1] + reached[-1]))
        phase = near - np.repeat(group_first, np.diff(bounds))
        phase = phase * _GOLDEN
        phase -= np.floor(phase)
        return _Buckets(owner, start[entry], taken[entry], stride[entry], phase)


def _distinct_cells(cells: I64, groups: I64) -> tuple[I64, I64, I64]:
    """The distinct (group, cell) of the queries: their cells (u, 3) and groups (u,), ordered by group, and each
    query's index among them."""
    lo = np.minimum.reduce(cells, axis=0)
    span = np.maximum.reduce(cells, axis=0) - lo + 1
    if float(np.prod(span, dtype=np.float64)) * (int(groups[-1]) + 1) < 2.0**62:  # one int64 key per (group, cell)
        key = (groups * span[0] + (cells[:, 0] - lo[0])) * span[1] + (cells[:, 1] - lo[1])
        key = key * span[2] + (cells[:, 2] - lo[2])
        order = np.argsort(key)
        key = key[order]
        new = np.ones(len(order), dtype=bool)
        np.not_equal(key[1:], key[:-1], out=new[1:])
    else:
        order = np.lexsort((cells[:, 2], cells[:, 1], cells[:, 0], groups))
        new = np.ones(len(order), dtype=bool)
        new[1:] = (groups[order[1:]] != groups[order[:-1]]) | (cells[order[1:]] != cells[order[:-1]]).any(axis=1)
    cell_of = np.empty(len(order), dtype=np.int64)
    cell_of[order] = np.cumsum(new) - 1
    first = order[new]
    return cells[first], groups[first], cell_of


def _near_bits(fraction: F64, magnitude: F64) -> I64:
    """Per query, a bit mask of the 3 x 3 x 3 cells around it (bit ``9·ix + 3·iy + iz``, the order of
    :func:`_hash_around`) whose nearest point is within one cell size of the query: ``fraction`` (q, 3) is the
    query's position in its own cell, in cell units. The margin covers rounding (the query's and the points'
    cell coordinates); far from the origin (``magnitude``, in cells, beyond 1e9) every cell counts as near."""
    gaps = np.empty((3, 3, len(fraction)))  # (axis, offset -1 / 0 / +1, query): squared gaps to those cells
    f = fraction.T
    np.multiply(f, f, out=gaps[:, 0])
    gaps[:, 1] = 0.0
    g = np.subtract(1.0, f, out=gaps[:, 2])
    g *= g
    d2 = gaps[0][:, None, None, :] + gaps[1][None, :, None, :] + gaps[2][None, None, :, :]
    near = d2.reshape(27, len(fraction)) <= 1.0 + 1e-6
    near[:, magnitude > 1e9] = True
    return _BITS @ near


class _Buckets(NamedTuple):
    owner: I64  # query of each (query, bucket) pair
    start: I64  # the bucket's first sorted slot
    taken: I64  # samples taken from it
    stride: F64  # slot step between samples, also their weight (1: every point)
    phase: F64  # sample k sits at slot floor((k + phase)·stride)


def _pair_sums(xyz: F64, point: F64, start: I64, taken: I64, stride: F64, phase: F64 | None, reach: F64,
               out: F64) -> None:
    """Σ stride·(P − Q)/|P − Q|² over the samples Q within ``reach`` (squared radius) of one block of (query P,
    bucket) pairs, ``point`` (3, pairs) holding each pair's P, into ``out`` (3, pairs).

    The block is laid out (sample, pair), so every operation runs along the long pair axis; ``taken[0]`` is the
    most samples of a pair in the block. Sample k sits at floor((k + phase)·stride) from the bucket's start (at
    k when ``phase`` is None: every point of the bucket); samples past ``taken`` are padding (their slots may
    point past the end of the table: gathered with clipping, weight 0).
    """
    samples = int(taken[0])
    index, deltas, d2, w, ok, mask = _WORK.arrays(samples, len(start))
    if phase is None:
        np.add(_K[:samples], start, out=index)
    else:
        np.add(_KF[:samples], phase, out=w)
        np.multiply(w, stride, out=w)
        np.copyto(index, w, casting="unsafe")  # floor: the offsets are >= 0
        np.add(index, start, out=index)
    for axis in range(3):  # loop over the three axes
        np.take(xyz[axis], index, out=deltas[axis], mode="clip")
        np.subtract(point[axis], deltas[axis], out=deltas[axis])
    dx, dy, dz = deltas
    np.multiply(dx, dx, out=d2)
    d2 += np.multiply(dy, dy, out=w)
    d2 += np.multiply(dz, dz, out=w)
    np.less_equal(d2, reach, out=ok)
    ok &= np.greater(d2, _SAME_POINT, out=mask)
    if int(taken[-1]) < samples:
        ok &= np.less(_K[:samples], taken, out=mask)  # padding
    np.maximum(d2, _SAME_POINT, out=d2)
    np.divide(stride, d2, out=w)
    w *= ok
    deltas *= w
    np.add.reduce(deltas, axis=1, out=out)


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
    same results as one group at a time."""
    out = [np.zeros((len(q), 3)) for q, _, _, _ in groups]
    live = [g for g, (q, p, _, strength) in enumerate(groups) if len(q) and len(p) and strength != 0.0]
    if not live:
        return out
    sizes = [len(groups[g][0]) for g in live]
    grid = SpatialHash([groups[g][1] for g in live], [groups[g][2] for g in live])
    query = np.concatenate([groups[g][0] for g in live])
    owner, start, taken, stride, phase = grid.buckets(query, sizes, per_bucket_limit)
    if len(owner) == 0:
        return out
    radii = [groups[g][2] for g in live]
    if all(r == radii[0] for r in radii):
        reach = radii[0] * radii[0]  # squared radius, shared
    else:
        reach = np.array([r * r for r in radii])[np.repeat(np.arange(len(live)), sizes)][owner]  # ... per pair
    # Pairs in the order they are computed: the sampled ones (all of per_bucket_limit samples, slots from the
    # phase), then the others, which take every point of their bucket, fullest first (a stable radix sort), so a
    # block of pairs holds about equal sample counts. Their parameters are laid out in that order once.
    sampled = stride > 1.0
    order = np.flatnonzero(sampled)
    split = len(order)
    rest = np.flatnonzero(~sampled)
    if len(rest):
        most = int(taken[rest].max())
        rest = rest[np.argsort((most - taken[rest]).astype(np.uint16) if most < 1 << 16 else -taken[rest],
                               kind="stable")]
        order = np.concatenate([order, rest])
    start, taken, stride = start[order], taken[order], stride[order]
    phase = phase[order[:split]]
    if not np.isscalar(reach):
        reach = reach[order]
    point = _WORK.table("point", 3 * len(order)).reshape(3, -1)
    query_xyz = np.ascontiguousarray(query.T)
    pair_owner = owner[order]
    for axis in range(3):  # loop over the three axes (1-d takes of contiguous rows are the fast ones)
        np.take(query_xyz[axis], pair_owner, out=point[axis])
    sums = _WORK.table("sums", 3 * len(order)).reshape(3, -1)
    lo = 0
    while lo < len(order):  # loop over blocks of pairs (bounded work arrays), not over particles
        hi = min(lo + max(1, _BLOCK_SLOTS // int(taken[lo])), split if lo < split else len(order))
        _pair_sums(grid.xyz, point[:, lo:hi], start[lo:hi], taken[lo:hi], stride[lo:hi],
                   phase[lo:hi] if lo < split else None, reach if np.isscalar(reach) else reach[lo:hi],
                   sums[:, lo:hi])
        lo = hi
    by_pair = _WORK.table("by_pair", 3 * len(order)).reshape(3, -1)
    for axis in range(3):  # loop over the three axes
        np.put(by_pair[axis], order, sums[axis])
    total = np.empty((len(query), 3))
    for axis in range(3):  # per query, its buckets summed in order
        total[:, axis] = np.bincount(owner, weights=by_pair[axis], minlength=len(query))
    bounds = np.cumsum([0] + sizes)
    for i, g in enumerate(live):  # loop over groups
        out[g] = total[bounds[i]: bounds[i + 1]] * groups[g][3]
    return out
