"""The toon smoke's simulation system in the demo as played: the autoplay drives the demo scene (no renderer), and
the CPU time of the ``toon_smoke.simulate`` system (this thread's, ``time.thread_time``) is summed over the
measured ticks.  The demo's puffs appear when targets burst (the first after about 30 ticks, then one or two alive
at a time), so the figure is what the puffs cost a tick on average, with the ticks that create a puff (its solid
masks and multigrid levels) among them; those are listed too.

To compare two versions of the code, run each checkout's copy in separate processes, alternating, a few times
each: the machine's load changes between runs more than one version differs from the next.

    .venv/bin/python bench/toon_smoke_demo_bench.py [--warmup 30] [--ticks 400]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from components.toon_smoke import ToonSmokeState  # noqa: E402
from engine.app import App  # noqa: E402
from game_demo.autoplay import AutoPilot  # noqa: E402

SCENE = ROOT / "configs" / "scenes" / "demo.toml"
SYSTEM = "toon_smoke.simulate"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--warmup", type=int, default=30, help="ticks before measuring (the first puff's kernels load)")
    parser.add_argument("--ticks", type=int, default=400)
    args = parser.parse_args()
    app = App(SCENE)
    app.pre_tick.append(AutoPilot())
    (system,) = [s for s in app.schedule.systems if s.name == SYSTEM]
    inner = system.fn
    ticks: list[tuple[float, int, int]] = []  # (ms, tick, volumes stepped)

    def timed(world, dt: float) -> None:
        volumes = sum(1 for _ in world.query(ToonSmokeState))
        start = time.thread_time()
        inner(world, dt)
        ticks.append(((time.thread_time() - start) * 1e3, world.tick, volumes))

    object.__setattr__(system, "fn", timed)
    for _ in range(args.warmup):
        app.step(1)
    ticks.clear()
    for _ in range(args.ticks):
        app.step(1)
    total = sum(ms for ms, _, _ in ticks)
    steps = sum(n for _, _, n in ticks)
    print(f"demo autoplay, {args.ticks} ticks after {args.warmup}: {steps} puff steps "
          f"({steps / args.ticks:.2f} a tick)")
    print(f"  {SYSTEM}: {total / args.ticks:.3f} ms a tick, {total / max(steps, 1):.3f} ms a puff step (thread CPU)")
    largest = sorted(ticks, reverse=True)[:4]
    print("  largest ticks: " + ", ".join(f"{ms:.1f} ms (tick {tick}, {n} puffs)" for ms, tick, n in largest))
    print(f"  state hash {app.state_hash()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
