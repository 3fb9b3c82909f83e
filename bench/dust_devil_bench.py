"""Dust devil benchmark (seeds/004): the paper's workload in frames per second, and the simulation step.

    .venv/bin/python bench/dust_devil_bench.py [--frames 60] [--skip-render]

Paper (section 5; Xeon 2.53 GHz, Visual C++, a 2012 GPU): 63 x 63 terrain at spacing 2, 3,500-5,000 real
particles drawn as 7,000-10,000 pseudo-particles, 640 x 480 accumulation images, 16 per time step: 13-17 fps.
Here: the same workload headless (EGL; Mesa llvmpipe on a machine without a GPU), one fixed simulation step per
frame, timed wall-clock with glFinish (median and best frame) and in process CPU time (all of llvmpipe's threads;
steadier than wall time when other jobs share the machine); then the simulation step alone for 100k particles
(the compiled particle kernel, systems/dust_devil/kernels.py, beside the numpy step it replaces: --numpy-step).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SCENE = """
[scene]
seed = 4
plugins = ["render", "dust_devil"]
[render]
width = {width}
height = {height}
[[entities]]
name = "desert"
[entities.components.Transform]
[entities.components.Terrain]
preset = "terrain/dust_devil_desert"   # 65 x 65 points = 64 x 64 polygons at spacing 2 (the paper: 63 x 63)
[[entities]]
name = "dust_devil"
[entities.components.Transform]
position = [0.0, -6.0, 0.0]
[entities.components.DustDevil]
preset = "dust_devil/paper"
particle_count = {particles}
{extra}
{cameras}
"""

ONE_VIEW = """
[[entities]]
name = "oblique"
[entities.components.Transform]
[entities.components.Camera]
fov = 50.0
controller = "orbit"
target = [0.0, 8.0, 0.0]
distance = 38.0
pitch = -15.0
"""

TWO_VIEWS = """
[[entities]]
name = "top"
[entities.components.Transform]
[entities.components.Camera]
projection = "orthographic"
ortho_height = 96.0
controller = "top"
distance = 100.0
far = 300.0
viewport = [0.0, 0.0, 0.5, 1.0]
priority = 1
""" + ONE_VIEW.replace('pitch = -15.0', 'pitch = -15.0\nviewport = [0.5, 0.0, 0.5, 1.0]')


SCATTER_STAGE = "auto"  # --scatter-stage
PIXEL_TERRAIN = False  # --pixel-terrain


def make_app(width: int, height: int, particles: int, cameras: str, extra: str = ""):
    from engine.app import App

    folder = Path(tempfile.mkdtemp(prefix="dust_devil_bench_"))
    path = folder / "bench.toml"
    path.write_text(SCENE.format(width=width, height=height, particles=particles, cameras=cameras, extra=extra))
    return App(path, configs_root=ROOT / "configs")


def bench_render(label: str, width: int, height: int, particles: int, cameras: str, frames: int,
                 extra: str = "", passes: bool = False, overlap: bool = True, orbit: float = 0.0,
                 cache: bool = True) -> tuple[float, float]:
    """(median wall-clock frame, median CPU time per frame) of one fixed step then the frame, glFinish'd; prints
    them with the best frame, the process CPU time per frame (all of llvmpipe's threads: steadier than wall time
    on a shared machine) and the PBVR path; ``overlap``: then the frame with the next step run while llvmpipe
    rasterises it (as the engine runs); ``passes``: then the per-pass times (each pass followed by glFinish, so
    they add up to more than a pipelined frame); ``orbit``: degrees the orbit camera turns every frame (a moving
    camera: the static layer, terrain and sky, is drawn every frame); ``cache``: ``[render] static_layer_cache``."""
    from engine.render.components import Camera

    from engine.render.frontend import create_headless_context
    from engine.render.renderer import Renderer

    app = make_app(width, height, particles, cameras, extra)
    app.config.render.static_layer_cache = cache
    orbiting = [cam for _, (cam,) in app.world.query(Camera) if cam.config.controller == "orbit"]

    def step() -> None:  # one fixed step, the orbit camera turned first when the camera moves
        for cam in orbiting:
            cam.yaw = (cam.yaw + orbit) % 360.0
        app.step(1)

    app.step(1)  # emission + prewarm
    renderer = Renderer(app, create_headless_context(), width, height)
    feature = next(f for f in renderer.features if f.name == "dust_devil")
    if SCATTER_STAGE == "vertex" and feature.use_scatter(1):
        feature.compute = False  # A/B: the GL 4.2 vertex-stage scatter on a context that has compute shaders
    if PIXEL_TERRAIN:  # A/B: full-detail terrain chunks fetch the baked light per pixel too (no Gouraud variant)
        next(f for f in renderer.features if f.name == "terrain").vertex_shade = False
    for _ in range(3):  # warm up: shader compilation, pool allocation
        step()
        app.render_frame()
    renderer.ctx.finish()
    times, sims, cpus = [], [], []
    for _ in range(frames):
        t0, c0 = time.perf_counter(), time.process_time()
        step()
        t1 = time.perf_counter()
        app.render_frame()
        renderer.ctx.finish()
        times.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
        sims.append(t1 - t0)
    frame = statistics.median(times)
    path = feature.path if "pbvr = false" not in extra else "-"
    print(f"  {label:<50s} {1.0 / frame:6.1f} fps   (median frame {1e3 * frame:6.1f} ms, best {1e3 * min(times):6.1f}, "
          f"CPU {1e3 * statistics.median(cpus):6.1f} ms/frame, simulation {1e3 * statistics.median(sims):4.1f} ms; "
          f"PBVR {path})")
    if overlap:  # as the engine runs ([render] overlap_ticks): the next tick while llvmpipe rasterises the frame
        overlapped = []
        for _ in range(frames):
            t0 = time.perf_counter()
            app.render_frame(overlap=step)
            renderer.ctx.finish()
            overlapped.append(time.perf_counter() - t0)
        median = statistics.median(overlapped)
        print(f"  {'  the same, tick overlapped with the frame':<50s} {1.0 / median:6.1f} fps   (median frame "
              f"{1e3 * median:6.1f} ms, best {1e3 * min(overlapped):6.1f}; how the engine runs)")
    if passes:
        renderer.timer.enabled, renderer.timer.gpu = True, False
        renderer.timer.reset()
        for _ in range(min(frames, 20)):
            step()
            app.render_frame()
        print("    " + renderer.timer.report().replace("\n", "\n    "))
    renderer.release()
    return frame, statistics.median(cpus)


def bench_step(particles: int, extra: str, steps: int = 10, rounds: int = 3) -> float:
    """One fixed step in ms: the best of ``rounds`` rounds of CPU time (the step runs on one thread)."""
    app = make_app(320, 240, particles, "", extra + "\nprewarm_time = 0.0")
    app.step(2)
    best = float("inf")
    for _ in range(rounds):
        c0 = time.process_time()
        app.step(steps)
        best = min(best, (time.process_time() - c0) / steps)
    return 1e3 * best


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--skip-render", action="store_true")
    parser.add_argument("--passes", action="store_true", help="per-pass CPU times of the one-view workload")
    parser.add_argument("--scatter-stage", choices=("auto", "vertex"), default="auto",
                        help="vertex: the PBVR scatter in the vertex stage even where compute shaders run (A/B)")
    parser.add_argument("--pixel-terrain", action="store_true",
                        help="every terrain chunk fetches its baked light per pixel (A/B for the per-vertex variant)")
    parser.add_argument("--numpy-step", action="store_true",
                        help="also time the numpy particle step the compiled kernel replaces (A/B)")
    args = parser.parse_args()
    global SCATTER_STAGE, PIXEL_TERRAIN
    SCATTER_STAGE, PIXEL_TERRAIN = args.scatter_stage, args.pixel_terrain
    import os

    print("Dust devil (seeds/004) benchmark; load average at start "
          + ", ".join(f"{x:.2f}" for x in os.getloadavg()) + f" on {os.cpu_count()} CPUs")
    if not args.skip_render:
        import moderngl

        ctx = moderngl.create_standalone_context(backend="egl", require=330)
        print(f"GL: {ctx.info['GL_RENDERER']}")
        ctx.release()
        print("paper's workload: 64 x 64 terrain polygons, 5000 particles x 2 pseudo-particles, 16 repeats:")
        frame, cpu = bench_render("640 x 480, one view", 640, 480, 5000, ONE_VIEW, args.frames, passes=args.passes)
        print(f"  {'paper (Xeon 2.53 GHz, 2012)':<50s} {'13-17':>6s} fps   (here {1 / frame / 15.0:.2f}x the paper's "
              "mid-range; target >= 60 fps)")
        bench_render("640 x 480, one view, camera turning 0.5° a frame", 640, 480, 5000, ONE_VIEW, args.frames,
                     orbit=0.5)
        bench_render("640 x 480, one view, static layer cache off", 640, 480, 5000, ONE_VIEW, args.frames,
                     cache=False)
        bench_render("two 640 x 480 views (top + oblique), 1280 x 480", 1280, 480, 5000, TWO_VIEWS, args.frames)
        _, drag = bench_render("640 x 480, while dragging (R = 4)", 640, 480, 5000, ONE_VIEW, args.frames,
                               "repeats = 4\ndrag_repeats = 4")
        _, off = bench_render("640 x 480, PBVR off (real particles drawn)", 640, 480, 5000, ONE_VIEW, args.frames,
                              "pbvr = false")
        print(f"  PBVR cost (CPU per frame - the same with PBVR off): R = 16 {1e3 * (cpu - off):5.1f} ms, "
              f"R = 4 {1e3 * (drag - off):5.1f} ms = {1e6 * (cpu - off) / (5000 * 2 * 16):.3f} us per pseudo-particle")
    from systems.dust_devil import simulate

    kinds = [("compiled", True)] + ([("numpy", False)] if args.numpy_step else [])
    print("simulation step (one fixed step, terrain on; CPU time, best of 3 rounds; "
          + " / ".join(k for k, _ in kinds) + "):")
    for label, extra in [("nearest + midpoint (default)", ""), ("nearest + euler (paper's step)", 'integrator = "euler"'),
                         ("trilinear + midpoint", 'lookup = "trilinear"')]:
        for n in (5000, 100_000):
            figures = []
            for _, use in kinds:
                simulate.USE_KERNELS = use
                figures.append(f"{bench_step(n, extra):7.2f}")
            simulate.USE_KERNELS = True
            print(f"  {n:>7d} particles, {label:<32s} {' / '.join(figures)} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
