from dataclasses import dataclass

import pytest

from engine.events import Events
from engine.world import EntityError, World


@dataclass
class Pos:
    x: float = 0.0


@dataclass
class Vel:
    v: float = 1.0


@dataclass
class Frozen:
    pass


def test_spawn_get_has_remove_despawn():
    w = World()
    e = w.spawn(Pos(1.0), Vel(2.0))
    assert w.has(e, Pos, Vel) and w.get(e, Pos).x == 1.0
    assert w.remove(e, Vel).v == 2.0
    assert not w.has(e, Vel) and w.try_get(e, Vel) is None
    with pytest.raises(EntityError, match="has no Vel"):
        w.get(e, Vel)
    w.despawn(e)
    assert not w.alive(e)
    with pytest.raises(EntityError, match="does not exist"):
        w.add(e, Pos())


def test_ids_are_never_reused():
    w = World()
    a = w.spawn()
    w.despawn(a)
    b = w.spawn()
    assert b > a


def test_query_ascending_with_exclusion_and_cache_invalidation():
    w = World()
    ids = [w.spawn(Pos(i), Vel()) for i in range(5)]
    w.add(ids[2], Frozen())
    result = w.query(Pos, Vel, exclude=(Frozen,))
    assert [e for e, _ in result] == [ids[0], ids[1], ids[3], ids[4]]
    assert w.query(Pos, Vel, exclude=(Frozen,)) is result  # cached
    w.remove(ids[2], Frozen)  # structural change on an excluded type invalidates
    assert [e for e, _ in w.query(Pos, Vel, exclude=(Frozen,))] == ids
    w.despawn(ids[0])
    assert [e for e, _ in w.query(Pos, Vel, exclude=(Frozen,))] == ids[1:]
    replacement = Pos(99)
    w.add(ids[1], replacement)  # replacing a component refreshes the cached tuple
    assert w.query(Pos)[0][1][0] is replacement


def test_two_worlds_are_independent():
    a, b = World(), World()
    a.spawn(Pos())
    assert len(a) == 1 and len(b) == 0 and b.query(Pos) == []


def test_commands_are_deferred_until_applied():
    w = World()
    e = w.spawn(Pos())
    for entity, (pos,) in w.query(Pos):
        new = w.commands.spawn(Pos(5.0))
        w.commands.insert(entity, Vel(3.0))
        w.commands.despawn(entity)
        assert len(w.query(Pos)) == 1  # nothing changed while iterating
    assert not w.alive(new)
    assert w.commands.apply() == 3
    assert w.alive(new) and not w.alive(e)
    assert [x for x, _ in w.query(Pos)] == [new]


def test_commands_on_despawned_entities_are_skipped():
    w = World()
    e = w.spawn(Pos())
    w.commands.despawn(e)
    w.commands.despawn(e)
    w.commands.insert(e, Vel())
    w.commands.apply()
    assert not w.alive(e)


def test_resources_one_per_type():
    w = World()
    w.insert_resource(Pos(1.0))
    w.insert_resource(Pos(2.0))
    assert w.resource(Pos).x == 2.0
    with pytest.raises(EntityError, match="no resource"):
        w.resource(Vel)


def test_events_each_read_once_and_live_two_ticks():
    ev = Events()
    early = ev.reader(int)
    ev.send(1)
    ev.send(2)
    late = ev.reader(int, from_start=True)
    assert early.read() == [1, 2]
    assert early.read() == []
    ev.update()  # still readable during the next tick
    assert late.read() == [1, 2]
    ev.send(3)
    ev.update()
    ev.update()
    assert ev.pending(int) == []
    assert early.read() == []  # 3 was dropped before this reader looked; nothing is read twice


def test_each_and_queries_stay_exact_under_incremental_updates():
    w = World()
    ids = [w.spawn(Pos(i), Vel()) for i in range(6)]
    each, both, no_frozen = w.each(Pos), w.query(Pos, Vel), w.query(Pos, exclude=(Frozen,))
    late = w.spawn(Pos(10))  # appended to the cached lists in place
    w.despawn(ids[2])
    w.add(ids[4], Frozen())
    w.remove(ids[5], Vel)
    w.add(ids[0], Pos(-1))  # replacement
    fresh = World()  # the same state built from scratch must give the same rows
    expect_each = sorted((e, w.get(e, Pos)) for e in w.entities if w.has(e, Pos))
    assert w.each(Pos) is each and each == expect_each
    assert [e for e, _ in both] == [ids[0], ids[1], ids[3], ids[4]] and both[0][1][0].x == -1
    assert [e for e, _ in no_frozen] == [ids[0], ids[1], ids[3], ids[5], late]
    assert fresh.each(Pos) == []
