"""Benchmark of the water_surface effect (seeds/003), figures printed beside the paper's.

1. The paper's case: a 26 × 26 water model with a box moving through it (section 3.1: about 60 fps on a
   Pentium 4 1.5 GHz). Measured: simulation steps per second of the water step (outline method), of a full
   engine tick (scripts + rigid bodies + water), and the re-triangulation of the render mesh (from scratch, and per
   frame along the box's path, where the previous frame's triangles are kept while they stay valid).
2. A 256 × 256 pond with 16 floating rigid bodies: milliseconds per engine tick, split into bodies and waves.

Run: ``python bench/water_bench.py`` (``--quick`` for fewer repetitions). Not part of the test suite.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engine.app import App  # noqa: E402
from components.water_surface import WaterState  # noqa: E402

PAPER_FPS = 60.0
TARGET_SMALL = 100.0 * PAPER_FPS  # ≥ 100× the paper's rate
TARGET_LARGE_MS = 4.0


def _scene(resolution: int, spacing: float, bodies: str, wave_speed: float = 1.5) -> str:
    return f"""
[scene]
name = "bench"
seed = 1
plugins = ["water_surface"]

[[entities]]
name = "water"
[entities.components.Transform]
position = [0.0, 0.0, 0.0]
[entities.components.WaterSurface]
resolution = [{resolution}, {resolution}]
spacing = {spacing}
wave_speed = {wave_speed}
damping = 0.995
depth = 2.0
{bodies}
"""


MOVING_BOX = """
[[entities]]
name = "box"
scripts = [{ name = "water_surface.glide", params = { velocity = [1.0, 0.0, 0.3], distance = 5.0 } }]
[entities.components.Transform]
position = [-2.5, 0.0, -0.7]
rotation = [20.0, 0.0, 0.0]
scale = [2.0, 0.8, 1.2]
[entities.components.RigidBody]
kinematic = true
"""


def _floating(n: int, extent: float, rng: np.random.Generator) -> str:
    out = []
    for i in range(n):
        x, z = rng.uniform(-0.4 * extent, 0.4 * extent, 2)
        shape = "sphere" if i % 4 == 3 else "box"
        scale = [1.0, 1.0, 1.0] if shape == "sphere" else [float(v) for v in rng.uniform(0.8, 1.8, 3).round(2)]
        mass = float(rng.uniform(0.3, 0.7) * 1000 * (0.5236 if shape == "sphere" else np.prod(scale)))
        out.append(f"""
[[entities]]
name = "body-{i}"
[entities.components.Transform]
position = [{x:.2f}, 0.3, {z:.2f}]
rotation = [{rng.uniform(0, 90):.1f}, {rng.uniform(-8, 8):.1f}, {rng.uniform(-8, 8):.1f}]
scale = {scale}
[entities.components.RigidBody]
shape = "{shape}"
mass = {mass:.1f}
""")
    return "".join(out)


def _timed(fn, repeat: int) -> float:
    """Median seconds of ``fn`` over ``repeat`` runs."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def _system_times(app: App, ticks: int) -> dict[str, float]:
    """Milliseconds per tick of each water_surface system (wrapping the schedule's functions)."""
    totals: dict[str, float] = {}
    for system in app.schedule.systems:
        if system.name.startswith("water_surface.") and system.name != "water_surface.check":
            fn = system.fn

            def timed(world, dt, fn=fn, name=system.name):
                start = time.perf_counter()
                fn(world, dt)
                totals[name] = totals.get(name, 0.0) + time.perf_counter() - start

            system.fn = timed
    app.step(ticks)
    return {name: 1e3 * t / ticks for name, t in totals.items()}


def bench_small(folder: Path, quick: bool) -> None:
    path = folder / "small.toml"
    path.write_text(_scene(26, 0.4, MOVING_BOX), encoding="utf-8")
    app = App(path)
    app.step(60)
    ticks = 300 if quick else 1200
    tick_s = _timed(lambda: app.step(ticks), 3) / ticks
    split = _system_times(app, ticks)
    from systems.water_surface.mesh import retriangulate

    state = app.world.query(WaterState)[0][1][0]
    mesh_s = _timed(lambda: retriangulate(26, 26, state.point_uv, state.point_kind, state.segments), 200)
    frames = []
    for _ in range(120):  # the outline of consecutive frames, as the render feature sees it
        app.step(1)
        frames.append((state.point_uv.copy(), state.point_kind.copy(), state.segments.copy()))

    def sequence() -> None:
        previous = None
        for uv, kind, segments in frames:
            mesh = retriangulate(26, 26, uv, kind, segments, previous)
            reused.append(previous is not None and mesh.triangles is previous.triangles)
            previous = mesh

    reused: list[bool] = []
    frame_s = _timed(sequence, 5) / len(frames)
    reuse_share = sum(reused[:len(frames)]) / len(frames)
    wave_ms = split["water_surface.waves"]
    print("1. The paper's 26 x 26 pool with a moving box (outline method)")
    print(f"   paper (Pentium 4 1.5 GHz, DirectX 9):       ~{PAPER_FPS:.0f} frames/s")
    print(f"   water step (outline waves):                 {1e3 / wave_ms:8.0f} steps/s  ({wave_ms:.3f} ms)"
          f"  = {1e3 / wave_ms / PAPER_FPS:.0f}x the paper (target >= 100x, {TARGET_SMALL:.0f}/s)")
    print(f"   full engine tick (script, bodies, water):   {1 / tick_s:8.0f} ticks/s  ({1e3 * tick_s:.3f} ms)"
          f"  = {1 / tick_s / PAPER_FPS:.0f}x")
    print(f"   render mesh re-triangulation, from scratch: {1e3 * mesh_s:8.3f} ms "
          f"({len(state.point_uv)} added points, {len(state.segments)} outline segments)")
    print(f"   re-triangulation per frame, moving box:      {1e3 * frame_s:8.3f} ms "
          f"(previous frame's triangles kept in {100 * reuse_share:.0f} % of {len(frames)} frames)")
    print(f"   step + re-triangulation (the paper's frame): {1 / (wave_ms / 1e3 + frame_s):8.0f} /s")


def bench_large(folder: Path, quick: bool) -> None:
    rng = np.random.default_rng(7)
    path = folder / "large.toml"
    spacing = 0.15
    extent = 255 * spacing
    path.write_text(_scene(256, spacing, _floating(16, extent, rng), wave_speed=2.0), encoding="utf-8")
    app = App(path)
    app.step(120)  # let the bodies land
    ticks = 60 if quick else 240
    tick_ms = 1e3 * _timed(lambda: app.step(ticks), 3) / ticks
    split = _system_times(app, ticks)
    state = app.world.query(WaterState)[0][1][0]
    print(f"2. A 256 x 256 pond ({extent:.1f} m) with 16 floating bodies")
    print(f"   engine tick:                                {tick_ms:8.3f} ms/step  (target <= {TARGET_LARGE_MS} ms)")
    for name, ms in sorted(split.items()):
        print(f"     {name:<40s} {ms:8.3f} ms")
    print(f"   added points on the outlines: {len(state.point_uv)}, vertices inside bodies: {int(state.solid.sum())}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        bench_small(Path(folder), args.quick)
        bench_large(Path(folder), args.quick)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
