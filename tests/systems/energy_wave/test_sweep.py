"""The collision sweep tests every segment against every collider's bounds at once: it must give exactly what a
ray cast per collider over its own candidates gives (first hits, ties, triggers, NaN segments, allowed masks)."""

import numpy as np
import pytest

from engine.collider import Collider
from engine.heightfield import HeightField
from engine.spatial import Transform, quat_from_euler
from systems.energy_wave.simulate import ColliderEntry, SweepResult, collider_bounds, sweep, sweep_candidates


def _reference_sweep(p0, p1, colliders, allowed=None) -> SweepResult:
    """The sweep one collider at a time: its candidates axis by axis (some end >= lo, some end <= hi), then its
    ray cast, in collider order (the code the broadcast candidate test replaced)."""
    n = len(p0)
    best_t = np.full(n, np.inf)
    best_c = np.full(n, -1, dtype=np.int64)
    best_n = np.zeros((n, 3))
    trigger_hits = []
    for index, entry in enumerate(colliders):  # loop over colliders
        candidate = np.ones(n, dtype=bool) if allowed is None else allowed[:, index].copy()
        if entry.lo is not None:
            for axis in range(3):  # loop over the three axes
                a, b = p0[:, axis], p1[:, axis]
                candidate &= (a >= entry.lo[axis]) | (b >= entry.lo[axis])
                candidate &= (a <= entry.hi[axis]) | (b <= entry.hi[axis])
        rows = np.flatnonzero(candidate)
        if rows.size == 0:
            continue
        hit, t, normal = entry.collider.ray_cast(p0[rows], p1[rows] - p0[rows], entry.transform, max_t=1.0)
        if entry.collider.is_trigger:
            enter = hit & (t > 0.0)
            trigger_hits.append((index, rows[enter], t[enter]))
            continue
        better = hit & (t < best_t[rows])
        rows = rows[better]
        best_t[rows], best_c[rows] = t[better], index
        best_n[rows] = normal[better]
    triggers = []
    for index, rows, t in trigger_hits:
        keep = t <= best_t[rows]
        rows, t = rows[keep], t[keep]
        if rows.size:
            triggers.append((index, rows, p0[rows] + t[:, None] * (p1[rows] - p0[rows])))
    return SweepResult(best_t, best_c, best_n, triggers)


def _entry(entity: int, collider: Collider, transform: Transform) -> ColliderEntry:
    return ColliderEntry(entity, collider, transform, *collider_bounds(collider, transform))


def _scene() -> list[ColliderEntry]:
    """Bounded and unbounded colliders, overlapping: two identical boxes (equal t: the first index must win), a
    trigger behind a wall, a plane and a rotated height field (unbounded), an unrotated one (bounded above)."""
    rng = np.random.default_rng(5)
    field = HeightField(rng.uniform(-0.3, 0.3, (9, 9)), spacing=0.5, origin=np.array([-2.0, -2.0]))
    box = dict(shape="box", half_extents=np.array([0.6, 0.4, 0.3]))
    turned = quat_from_euler(0.4, 0.2, -0.3)
    return [
        _entry(1, Collider(**box), Transform(position=np.array([0.0, 0.5, -1.0]))),
        _entry(2, Collider(**box), Transform(position=np.array([0.0, 0.5, -1.0]))),  # the same box again
        _entry(3, Collider(shape="box", half_extents=np.array([0.5, 0.5, 0.5]), is_trigger=True),
               Transform(position=np.array([0.0, 0.5, -1.6]))),  # a trigger behind the boxes
        _entry(4, Collider(shape="plane", offset=-1.5), Transform()),
        _entry(5, Collider(shape="sphere", radius=0.7), Transform(position=np.array([1.2, 0.0, 0.5]),
                                                                  scale=np.array([1.0, 1.5, 1.0]))),
        _entry(6, Collider(shape="box", half_extents=np.array([0.3, 0.8, 0.2])),
               Transform(position=np.array([-1.0, 0.2, 0.4]), rotation=turned)),
        _entry(7, Collider(shape="heightfield", heightfield=field), Transform(position=np.array([0.0, -0.8, 0.0]))),
        _entry(8, Collider(shape="heightfield", heightfield=field),
               Transform(position=np.array([0.5, -1.0, 0.0]), rotation=turned)),
        _entry(9, Collider(shape="sphere", radius=0.4, is_trigger=True), Transform(position=np.array([0.0, 1.5, 0.0]))),
        _entry(10, Collider(shape="box", half_extents=np.array([0.2, 0.2, 0.2])),
               Transform(position=np.array([40.0, 40.0, 40.0]))),  # out of every segment's reach
    ]


def _segments(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random short and long segments over the scene, some with a NaN coordinate at one or both ends, some
    starting inside a collider with a NaN end (inside: a hit at t = 0 whatever the direction)."""
    rng = np.random.default_rng(seed)
    p0 = rng.uniform(-2.5, 2.5, (n, 3))
    p1 = p0 + rng.normal(0.0, 1.0, (n, 3)) * rng.choice([0.05, 0.5, 3.0], (n, 1))
    p1[: n // 10] = p0[: n // 10]  # segments of length zero
    for ends, at in ((p0, slice(n // 10, n // 5)), (p1, slice(n // 5, 3 * n // 10))):
        ends[at, rng.integers(0, 3, at.stop - at.start)] = np.nan  # one NaN coordinate at one end
    p0[3 * n // 10: 7 * n // 20] = np.nan
    p1[7 * n // 20: 2 * n // 5] = np.nan  # a whole end NaN, the other one anywhere
    inside = slice(2 * n // 5, 9 * n // 20)
    p0[inside] = rng.uniform([-0.5, 0.2, -1.2], [0.5, 0.8, -0.8], (inside.stop - inside.start, 3))  # in the boxes
    p1[inside, rng.integers(0, 3, inside.stop - inside.start)] = np.nan
    below = slice(9 * n // 20, n // 2)
    p0[below, 1] = -2.0  # under the plane
    p1[below] = np.nan
    return p0, p1


def _assert_same(got: SweepResult, want: SweepResult) -> None:
    for name in ("t", "collider", "normal"):
        a, b = getattr(got, name), getattr(want, name)
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), name
    assert len(got.triggers) == len(want.triggers)
    for (index, rows, points), (index_ref, rows_ref, points_ref) in zip(got.triggers, want.triggers):
        assert index == index_ref
        assert rows.tobytes() == rows_ref.tobytes() and points.tobytes() == points_ref.tobytes()


_FIELDS = [6, 7]  # the height fields' indices in _scene(): their ray cast rejects NaN rays (as it did before)
_BLOCK = 9  # segments per block of _exact_cases()


def _exact_cases(colliders: list[ColliderEntry]) -> tuple[np.ndarray, np.ndarray]:
    """Three blocks of segments: through the two boxes into the trigger behind them, then ending exactly on the
    first box's upper z face, then exactly on its lower x face (touched at t ≈ 1: some end <= hi, >= lo)."""
    box = colliders[0]
    x = np.linspace(-0.4, 0.4, _BLOCK)
    start = np.stack([x, np.full(_BLOCK, 0.5), np.full(_BLOCK, -0.3)], axis=1)
    through, on_z = start.copy(), start.copy()
    through[:, 2], on_z[:, 2] = -2.3, box.hi[2]
    side = np.stack([np.full(_BLOCK, -1.5), 0.5 + 0.1 * x, -1.0 + 0.1 * x], axis=1)
    on_x = side.copy()
    on_x[:, 0] = box.lo[0]
    return np.concatenate([start, start, side]), np.concatenate([through, on_z, on_x])


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("case", ["mask", "no mask, no height fields", "no mask, no NaN"])
def test_sweep_equals_one_ray_cast_per_collider_bit_for_bit(seed, case):
    colliders = _scene()
    p0, p1 = _segments(4000, seed)
    nan = np.isnan(p0).any(axis=1) | np.isnan(p1).any(axis=1)
    allowed = None
    if case == "mask":
        allowed = np.random.default_rng(seed + 10).random((len(p0), len(colliders))) < 0.8
        allowed[np.ix_(nan, _FIELDS)] = False
    elif case == "no mask, no height fields":
        colliders = [entry for index, entry in enumerate(colliders) if index not in _FIELDS]
    else:
        p0, p1, nan = p0[~nan], p1[~nan], nan[~nan]
    exact0, exact1 = _exact_cases(colliders)
    p0, p1 = np.concatenate([p0, exact0]), np.concatenate([p1, exact1])
    if allowed is not None:
        allowed = np.concatenate([allowed, np.ones((len(exact0), len(colliders)), dtype=bool)])
    want = _reference_sweep(p0, p1, colliders, allowed)
    _assert_same(sweep(p0, p1, colliders, allowed), want)
    # the cases that tell the semantics apart all occur: ties, triggers behind and before solids, segments that
    # just touch a box, NaN ends that start inside a box or under the plane (hit at t = 0)
    entities = [colliders[i].entity if i >= 0 else 0 for i in want.collider.tolist()]
    assert {1, 4, 5, 6} <= set(entities)
    second = np.flatnonzero(np.array(entities) == 2)  # the second identical box loses every tie to the first
    assert second.size == 0 if allowed is None else not allowed[second, 0].any()
    assert case == "no mask, no height fields" or {7, 8} <= set(entities)
    assert [colliders[index].entity for index, _, _ in want.triggers] == [3, 9]
    through = len(p0) - 3 * _BLOCK + np.arange(_BLOCK)
    alone = _reference_sweep(p0, p1, [colliders[2]]).triggers[0][1]  # the trigger alone is entered ...
    assert np.isin(through, alone).all() and not np.isin(through, want.triggers[0][1]).any()  # ... not behind
    assert (want.collider[-2 * _BLOCK:] == 0).all()  # touching segments hit
    assert {1, 4} <= {entities[i] for i in np.flatnonzero(nan)} or not nan.any()


def test_candidates_follow_the_bounds_and_the_mask():
    """The candidate matrix itself: NaN ends, unbounded colliders, the mask, and no segments at all."""
    colliders = _scene()
    p0 = np.array([[0.0, 0.5, -1.0], [np.nan, 0.5, -1.0], [np.nan] * 3, [30.0, 30.0, 30.0]])
    p1 = np.array([[0.0, 0.5, -1.0], [0.1, 0.5, -1.0], [np.nan] * 3, [50.0, 50.0, 50.0]])
    got = sweep_candidates(p0, p1, colliders)
    assert got.shape == (len(colliders), 4) and got.flags.c_contiguous
    assert got[0].tolist() == [True, True, False, False]  # one NaN end: the other decides; two: no box is met
    assert got[3].tolist() == [True] * 4 and got[7].tolist() == [True] * 4  # plane, rotated field: unbounded
    assert got[9].tolist() == [False, False, False, True]
    allowed = np.ones((4, len(colliders)), dtype=bool)
    allowed[:, 3] = allowed[1, 0] = False
    masked = sweep_candidates(p0, p1, colliders, allowed)
    assert masked[3].tolist() == [False] * 4 and masked[0].tolist() == [True, False, False, False]
    assert sweep_candidates(np.zeros((0, 3)), np.zeros((0, 3)), colliders).shape == (len(colliders), 0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_height_fields_bounds_keep_every_segment_that_hits_it_and_drop_those_beside_it(seed):
    """An unrotated height field is bounded on x and z by its footprint (it is solid only over it) and above by
    its highest sample: every segment its ray cast hits is a candidate, and segments beside the footprint are not."""
    entry = _scene()[6]
    assert entry.entity == 7 and np.isfinite(entry.lo[[0, 2]]).all() and entry.lo[1] == -np.inf
    p0, p1 = _segments(4000, seed)
    p0, p1 = p0 * 3.0, p1 * 3.0  # reach well beside the 4 x 4 footprint
    candidates = sweep_candidates(p0, p1, [entry])[0]
    hit, _, _ = entry.collider.ray_cast(p0, p1 - p0, entry.transform, max_t=1.0)
    assert hit.sum() > 50 and not (hit & ~candidates).any()
    beside = (np.fmin(p0[:, 0], p1[:, 0]) > 2.0 + 1e-6) | (np.fmax(p0[:, 2], p1[:, 2]) < -2.0 - 1e-6)
    assert beside.sum() > 100 and not (candidates & beside).any()
