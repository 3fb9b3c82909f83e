"""ECS benchmark: the workload of esper's examples/benchmark.py, run side by side with esper in one process.

Per entity count: entities are created in pairs (Position+Velocity+Health+Command, Position+Health+
Damageable), then one-, two- and three-component queries are each timed 50 times (minimum kept, as
esper's benchmark does).  A second workload runs a movement processor and a damage processor for 100
ticks, with a little spawn/despawn churn every tick (structural changes invalidate query caches).
Prints both times and the ratio (esper time / ecsfx time: > 1 means ecsfx is faster).
"""

from __future__ import annotations

import gc
import sys
import time
from dataclasses import dataclass

try:
    import esper
except ImportError:  # pragma: no cover
    sys.exit("esper is a bench-only dependency: pip install -e '.[bench]'")

from engine.world import World


@dataclass
class Velocity:
    x: int = 0
    y: int = 0


@dataclass
class Position:
    x: int = 0
    y: int = 0


@dataclass
class Health:
    hp: int = 100


@dataclass
class Command:
    attack: bool = False
    defend: bool = True


@dataclass
class Damageable:
    defense: int = 45


QUERIES = {1: (Position,), 2: (Position, Velocity), 3: (Position, Damageable, Health)}


def best_of(fn, repeats: int = 50) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best * 1e3


# ------------------------------------------------------------------ ecsfx side
def ecsfx_world(n: int) -> World:
    w = World()
    for _ in range(n // 2):
        w.spawn(Position(), Velocity(), Health(), Command())
        w.spawn(Position(), Health(), Damageable())
    return w


def ecsfx_query(w: World, types) -> float:
    if len(types) == 1:  # esper's get_component(T) yields (entity, component): World.each is the same walk
        def run():
            for _, _c in w.each(types[0]):
                pass
    else:
        def run():
            for _, _comps in w.query(*types):
                pass

    return best_of(run)


def ecsfx_ticks(n: int, ticks: int = 100) -> float:
    w = ecsfx_world(n)
    t0 = time.perf_counter()
    for tick in range(ticks):
        for _, (pos, vel) in w.query(Position, Velocity):
            pos.x += vel.x + 1
            pos.y += vel.y
        for _, (hp, dmg) in w.query(Health, Damageable):
            hp.hp -= 1 if dmg.defense < 50 else 0
        e = w.spawn(Position(), Velocity(), Health(), Command())
        if tick % 2:
            w.despawn(e)
    return (time.perf_counter() - t0) * 1e3


# ------------------------------------------------------------------ esper side
def esper_world(n: int) -> None:
    esper.clear_database()
    for _ in range(n // 2):
        esper.create_entity(Position(), Velocity(), Health(), Command())
        esper.create_entity(Position(), Health(), Damageable())


def esper_query(types) -> float:
    if len(types) == 1:
        def run():
            for _, _c in esper.get_component(types[0]):
                pass
    else:
        def run():
            for _, _c in esper.get_components(*types):
                pass
    return best_of(run)


def esper_ticks(n: int, ticks: int = 100) -> float:
    esper_world(n)
    t0 = time.perf_counter()
    for tick in range(ticks):
        for _, (pos, vel) in esper.get_components(Position, Velocity):
            pos.x += vel.x + 1
            pos.y += vel.y
        for _, (hp, dmg) in esper.get_components(Health, Damageable):
            hp.hp -= 1 if dmg.defense < 50 else 0
        e = esper.create_entity(Position(), Velocity(), Health(), Command())
        if tick % 2:
            esper.delete_entity(e, immediate=True)
    return (time.perf_counter() - t0) * 1e3


def main() -> None:
    print(f"ECS benchmark (esper {getattr(esper, 'version', '?')}), times in ms, ratio = esper / ecsfx")
    print(f"{'workload':<34s}{'entities':>9s}{'ecsfx':>10s}{'esper':>10s}{'ratio':>8s}")
    ratios = []
    for n in (1000, 5000, 20000):
        w = ecsfx_world(n)
        esper_world(n)
        for k, types in QUERIES.items():
            ours = theirs = float("inf")
            for _ in range(3):  # interleaved rounds: neither side profits from running second (warm caches)
                theirs = min(theirs, esper_query(types))
                ours = min(ours, ecsfx_query(w, types))
            ratios.append(theirs / ours)
            print(f"{f'query {k} component(s), min of 50':<34s}{n:>9d}{ours:>10.3f}{theirs:>10.3f}{theirs / ours:>8.2f}")
        del w
        gc.collect()
        ours, theirs = ecsfx_ticks(n), esper_ticks(n)
        ratios.append(theirs / ours)
        print(f"{'2 processors x 100 ticks + churn':<34s}{n:>9d}{ours:>10.1f}{theirs:>10.1f}{theirs / ours:>8.2f}")
        gc.collect()
    geo = 1.0
    for r in ratios:
        geo *= r
    print(f"geometric mean ratio: {geo ** (1 / len(ratios)):.2f}x (target >= 1, aim 2)")


if __name__ == "__main__":
    main()
