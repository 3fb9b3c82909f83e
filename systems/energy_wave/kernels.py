"""Compiled kernels (``engine.jit.kernel``) of the energy wave's per-step loops: the neighbour repulsion R.

R (eq. 3.3, seeds/000) needs, for each particle that hits this step, the points within the repulsion radius
around it: a uniform grid hashed into a table (Müller, Ten Minute Physics #11). In numpy this took dozens of
passes over (query, bucket) and (sample, pair) arrays; here it is two passes of compiled loops with no
temporaries:

1. :func:`hash_points`: each group's points counted per bucket, the counts turned into bucket starts, and the
   points placed in bucket order (a stable counting sort);
2. :func:`repulsion_sums`: each query scans the buckets of the 3 x 3 x 3 cells around its own and sums
   r (P − Q)/|P − Q|² over the points Q within reach.

The order of every float operation is fixed (see :func:`repulsion_sums`), so the result is the same bits in
every run and process.
"""

from __future__ import annotations

import math

import numpy as np

from engine.jit import kernel

PRIME_X, PRIME_Y, PRIME_Z = 73856093, 19349663, 83492791  # the hash's primes (Teschner et al. 2003)
GOLDEN = 0.6180339887498949  # low-discrepancy phases of the sampled buckets
SAME_POINT = 1e-18  # squared distance under which a neighbour counts as "at the same position"
NEAR_MARGIN = 1e-6  # a cell is near when its squared gap is <= 1 + this (in cell units): covers rounding
FAR = 1e9  # beyond this many cells from the origin every cell around a query counts as near


@kernel(inline="always")
def _bucket(ix: int, iy: int, iz: int, mask: int) -> int:
    """Cell (ix, iy, iz) -> bucket in [0, mask]: (ix·p1 xor iy·p2 xor iz·p3) and mask (the table a power of 2;
    the products wrap around in 64 bits)."""
    return ((ix * PRIME_X) ^ (iy * PRIME_Y) ^ (iz * PRIME_Z)) & mask


@kernel
def hash_points(points, first, cells, offsets, tables, keys, counts, starts, fill, xyz):  # pragma: no cover
    """Hash each group's points into its own table (group g: points ``first[g]:first[g + 1]``, cell size
    ``cells[g]``, buckets ``offsets[g]:offsets[g] + tables[g]`` of the global table), counting sort by bucket.

    Writes ``counts`` and ``starts`` (per global bucket) and ``xyz`` (n, 3): the points in bucket order, each
    bucket's points in their input order, a group's points in its own slots ``first[g]:first[g + 1]``.
    ``keys`` and ``fill`` are work arrays (n and buckets long).
    """
    for g in range(len(tables)):  # loop over groups, then over their points: compiled
        size = cells[g]
        mask = tables[g] - 1
        base = offsets[g]
        for b in range(base, base + tables[g]):
            counts[b] = 0
        for i in range(first[g], first[g + 1]):
            key = base + _bucket(int(math.floor(points[i, 0] / size)), int(math.floor(points[i, 1] / size)),
                                 int(math.floor(points[i, 2] / size)), mask)
            keys[i] = key
            counts[key] += 1
    total = 0
    for b in range(len(counts)):  # exclusive prefix sum: the bucket starts
        starts[b] = total
        fill[b] = total
        total += counts[b]
    for i in range(len(keys)):
        slot = fill[keys[i]]
        fill[keys[i]] = slot + 1
        xyz[slot, 0] = points[i, 0]
        xyz[slot, 1] = points[i, 1]
        xyz[slot, 2] = points[i, 2]


@kernel(inline="always")
def _buckets_around(cx: int, cy: int, cz: int, mask: int, base: int, around):  # pragma: no cover
    """The buckets of the 27 cells around (cx, cy, cz) as ``(global bucket << 5) | offset`` sorted ascending in
    ``around`` (27,): offset 9·ix + 3·iy + iz for the cell (cx + ix − 1, cy + iy − 1, cz + iz − 1)."""
    for o in range(27):
        b = _bucket(cx + o // 9 - 1, cy + (o // 3) % 3 - 1, cz + o % 3 - 1, mask)
        key = ((base + b) << 5) | o
        j = o
        while j > 0 and around[j - 1] > key:  # insertion sort: 27 entries
            around[j] = around[j - 1]
            j -= 1
        around[j] = key


@kernel(inline="always")
def _near_bits(fx: float, fy: float, fz: float) -> int:
    """Bit mask of the 27 cells around a query (bit 9·ix + 3·iy + iz) whose nearest point is within one cell
    size of the query, (fx, fy, fz) its position in its own cell in cell units (the gaps: f² below, 0 in the
    cell, (1 − f)² above)."""
    bits = 0
    for o in range(27):
        ix, iy, iz = o // 9, (o // 3) % 3, o % 3
        gx = fx * fx if ix == 0 else (0.0 if ix == 1 else (1.0 - fx) * (1.0 - fx))
        gy = fy * fy if iy == 0 else (0.0 if iy == 1 else (1.0 - fy) * (1.0 - fy))
        gz = fz * fz if iz == 0 else (0.0 if iz == 1 else (1.0 - fz) * (1.0 - fz))
        if gx + gy + gz <= 1.0 + NEAR_MARGIN:
            bits |= 1 << o
    return bits


@kernel
def repulsion_sums(query, first, cells, offsets, tables, strength, limit, counts, starts, xyz,
                   out):  # pragma: no cover
    """R = r Σ (P − Q)/|P − Q|² (eq. 3.3, the sign away from the neighbours) of every query P over the hashed
    points Q (:func:`hash_points`) with 1e-18 < |P − Q|² <= radius², group by group (group g: queries
    ``first[g]:first[g + 1]``, radius ``cells[g]``, r ``strength[g]``), into ``out`` (m, 3).

    Each query scans the distinct non-empty buckets of the 27 cells around its own in ascending order, skipping
    those that only cells beyond its reach map to (their nearest point is farther than the radius: exact).
    Sampling (bounded cost in crowded cells): when ``limit`` > 0 and some bucket around some query of a group
    holds more than ``limit`` points, that group takes at most ``limit`` points from each bucket: for a bucket of
    c > limit points, sample k sits at slot floor((k + phase)·c/limit) with weight c/limit, the phase the
    golden-ratio sequence over the group's (query, non-empty bucket) pairs — an unbiased estimate of the sum.

    Float order (fixed): per (query, bucket) the samples are summed in slot order, the buckets' sums then added
    in ascending bucket order starting from 0, and the total multiplied by r. A sample out of reach adds
    (P − Q)·0 = ±0, which leaves every sum as it was (0 + −0 = 0), so the reach test is a select, not a branch
    (about half the samples are in reach: a branch on it mispredicts).
    """
    around = np.empty(27, dtype=np.int64)
    n = xyz.shape[0]
    for g in range(len(tables)):  # loop over groups, then over their queries: compiled
        size = cells[g]
        reach = size * size
        mask = tables[g] - 1
        base = offsets[g]
        sampled = False
        if limit > 0:  # does a query of the group reach a bucket of more than `limit` points?
            for q in range(first[g], first[g + 1]):
                _buckets_around(int(math.floor(query[q, 0] / size)), int(math.floor(query[q, 1] / size)),
                                int(math.floor(query[q, 2] / size)), mask, base, around)
                for o in range(27):
                    if counts[around[o] >> 5] > limit:
                        sampled = True
                if sampled:
                    break
        serial = 0  # the group's (query, non-empty bucket) pairs so far
        for q in range(first[g], first[g + 1]):
            px, py, pz = query[q, 0], query[q, 1], query[q, 2]
            sx, sy, sz = px / size, py / size, pz / size
            cx, cy, cz = math.floor(sx), math.floor(sy), math.floor(sz)
            if max(abs(sx), abs(sy), abs(sz)) > FAR:
                near = (1 << 27) - 1
            else:
                near = _near_bits(sx - cx, sy - cy, sz - cz)
            _buckets_around(int(cx), int(cy), int(cz), mask, base, around)
            tx = ty = tz = 0.0
            o = 0
            while o < 27:  # each distinct bucket once, with the bits of every offset that maps to it
                bucket = around[o] >> 5
                bits = 0
                while o < 27 and around[o] >> 5 == bucket:
                    bits |= 1 << (around[o] & 31)
                    o += 1
                count = counts[bucket]
                if count == 0:
                    continue
                pair = serial
                serial += 1
                if bits & near == 0:
                    continue
                taken = min(count, limit) if sampled else count
                stride = count / taken
                start = starts[bucket]
                bx = by = bz = 0.0
                if stride > 1.0:
                    phase = pair * GOLDEN
                    phase -= math.floor(phase)
                    for k in range(taken):
                        slot = min(start + int((k + phase) * stride), n - 1)
                        wx, wy, wz = _push(px, py, pz, xyz, slot, stride, reach)
                        bx += wx
                        by += wy
                        bz += wz
                else:
                    for slot in range(start, start + count):
                        wx, wy, wz = _push(px, py, pz, xyz, slot, stride, reach)
                        bx += wx
                        by += wy
                        bz += wz
                tx += bx
                ty += by
                tz += bz
            out[q, 0] = tx * strength[g]
            out[q, 1] = ty * strength[g]
            out[q, 2] = tz * strength[g]


@kernel(inline="always")
def _push(px, py, pz, xyz, slot, stride, reach):
    """Eq. 3.3's term of neighbour ``slot`` on the point (px, py, pz): (p − q) · stride / |p − q|², zero out of
    reach or at the same point (a select: half the samples are in reach, a branch would be mispredicted)."""
    dx, dy, dz = px - xyz[slot, 0], py - xyz[slot, 1], pz - xyz[slot, 2]
    d2 = dx * dx + dy * dy + dz * dz
    w = stride / d2 if d2 <= reach and d2 > SAME_POINT else 0.0
    return dx * w, dy * w, dz * w


@kernel(inline="always")
def _inside(points, i, lo, hi) -> bool:
    """lo <= points[i] <= hi on every axis (NaN: outside), without branches (bitwise and of the tests)."""
    x, y, z = points[i, 0], points[i, 1], points[i, 2]
    return (lo[0] <= x) & (x <= hi[0]) & (lo[1] <= y) & (y <= hi[1]) & (lo[2] <= z) & (z <= hi[2])


@kernel
def gather_in_box(position, pattern, count, extra, lo, hi, out) -> int:  # pragma: no cover
    """The neighbours Q of eq. 3.3 near one emitter's impact, in one pass: the rows of ``position[:count]`` whose
    particle has already hit (``pattern`` >= 0) and then the rows of ``extra`` (this step's hits) that lie in the
    box ``lo`` .. ``hi`` (the queries' box grown by the radius), in index order, into ``out`` (room for
    ``count + len(extra)`` rows); returns how many. Branch-free compaction: every row is written at the next
    free slot, which advances only for the rows kept (the tests are data-dependent: branches mispredict)."""
    k = 0
    for i in range(count):
        out[k, 0] = position[i, 0]
        out[k, 1] = position[i, 1]
        out[k, 2] = position[i, 2]
        k += (pattern[i] >= 0) & _inside(position, i, lo, hi)
    for i in range(len(extra)):
        out[k, 0] = extra[i, 0]
        out[k, 1] = extra[i, 1]
        out[k, 2] = extra[i, 2]
        k += _inside(extra, i, lo, hi)
    return k


@kernel
def advance_particles(position, velocity, age, pattern, count, dt, hold_irregular):  # pragma: no cover
    """One pass over an emitter's live particles at the start of a step: age += dt; the beam particles
    (``pattern`` < 0) listed with their positions before the move (their swept segments start there; for one
    emitted during the last step, younger than ``dt``, its birth point on the emitter, x - age·v, so that the
    stretch it was placed ahead of the emitter is swept too); every
    particle moved x += v·dt except, when ``hold_irregular``, the irregular ones (``pattern`` >= 0 and odd), which
    are listed instead: eq. 3.5 first steers them from their unmoved positions (then :func:`move_rows`).

    Returns (beam slots, their start positions (b, 3), irregular slots), slots ascending."""
    beam = np.empty(count, dtype=np.int64)
    start = np.empty((count, 3))
    irregular = np.empty(count if hold_irregular else 0, dtype=np.int64)
    b = 0
    r = 0
    for i in range(count):
        born = age[i] < dt  # emitted during the last step, at the emitter, and not swept since
        back = age[i] if born else 0.0
        age[i] += dt
        code = pattern[i]
        if code < 0:
            beam[b] = i
            start[b, 0] = position[i, 0] - back * velocity[i, 0]
            start[b, 1] = position[i, 1] - back * velocity[i, 1]
            start[b, 2] = position[i, 2] - back * velocity[i, 2]
            b += 1
        elif hold_irregular and code & 1 == 1:
            irregular[r] = i
            r += 1
            continue
        position[i, 0] += velocity[i, 0] * dt
        position[i, 1] += velocity[i, 1] * dt
        position[i, 2] += velocity[i, 2] * dt
    return beam[:b].copy(), start[:b].copy(), irregular[:r].copy()


@kernel
def move_rows(position, velocity, rows, dt):  # pragma: no cover
    """x += v·dt for the particles ``rows`` (the irregular ones, once steered)."""
    for i in rows:
        position[i, 0] += velocity[i, 0] * dt
        position[i, 1] += velocity[i, 1] * dt
        position[i, 2] += velocity[i, 2] * dt


@kernel
def dead_moves(age, lifetime, count):  # pragma: no cover
    """The particles whose life is over (age > lifetime + 1e-9) and how the buffer closes their gaps: returns
    (dead count, holes, movers): the dead slots below the new count ``count − dead`` (ascending) and as many live
    slots at or above it (ascending), which move into them in that order."""
    dead = 0
    for i in range(count):
        dead += age[i] > lifetime[i] + 1e-9
    keep = count - dead
    holes = np.empty(dead + 1, dtype=np.int64)  # one spare slot: each index is written, then kept or overwritten
    movers = np.empty(dead + 1, dtype=np.int64)
    h = 0
    for i in range(keep):  # branch-free: which particles died is data, a branch on it mispredicts
        holes[h] = i
        h += age[i] > lifetime[i] + 1e-9
    m = 0
    for i in range(keep, count):
        movers[m] = i
        m += not age[i] > lifetime[i] + 1e-9
    return dead, holes[:h].copy(), movers[:m].copy()
