"""Demo benchmark: frame time of the demo at 1280x720 headless (autoplay driving it), with the per-pass
breakdown from the profiler (CPU time with a GL finish per pass, which is exact on llvmpipe), and the
simulation tick time.  Target: >= 30 fps on llvmpipe.

Three loops are timed (the last twice):

* one fixed tick, then the frame (serial);
* the tick overlapped with the frame's rasterisation (``[render] overlap_ticks``);
* the real-time loop, as the window runs the game: ``App.advance`` with the measured length of the previous
  frame, so the fixed 60 Hz clock runs as many ticks as that time holds (below 60 fps, more than one a frame).
  This is the frame rate a player sees.  It also prints the CPU time per frame of the main thread (Python, the
  simulation, the driver's vertex work and binning) and of the other threads (llvmpipe's rasteriser threads):
  on a 2-core machine their sum over two is the floor of the frame time.  It runs at the set render scale, then
  again with ``[render] dynamic_resolution`` as the demo's window has it (the render scale lowered while frames
  miss 30 fps), with the share of frames drawn at each scale.

Then the per-pass breakdown of a frame, where the main thread blocks, and last the tick by system (CPU time of
each).
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.app import App  # noqa: E402
from engine.render.frontend import create_headless_context  # noqa: E402
from engine.render.renderer import Renderer  # noqa: E402
from game_demo.autoplay import AutoPilot  # noqa: E402

SCENE = Path(__file__).resolve().parents[1] / "configs" / "scenes" / "demo.toml"


def main(width: int = 1280, height: int = 720, warmup: int = 30, frames: int = 60) -> None:
    ctx = create_headless_context()
    app = App(SCENE)
    app.pre_tick.append(AutoPilot(window=(width, height)))
    renderer = Renderer(app, ctx, width, height)
    t0 = time.perf_counter()
    for _ in range(warmup):
        app.step(1)
        app.render_frame()
    ctx.finish()
    print(f"GL renderer: {ctx.info['GL_RENDERER']}; warm-up {warmup} frames (incl. bakes) "
          f"{time.perf_counter() - t0:.1f} s")
    ticks, draws = [], []
    for _ in range(frames):  # plain frames: no per-pass synchronisation; the tick, then the frame
        t = time.perf_counter()
        app.step(1)
        ticks.append((time.perf_counter() - t) * 1e3)
        t = time.perf_counter()
        app.render_frame()
        ctx.finish()
        draws.append((time.perf_counter() - t) * 1e3)
    frame = [a + b for a, b in zip(ticks, draws)]
    overlapped, overlapped_ticks = [], []

    def tick() -> None:
        t = time.perf_counter()
        app.step(1)
        overlapped_ticks.append((time.perf_counter() - t) * 1e3)

    for _ in range(frames):  # as the demo runs ([render] overlap_ticks): the next tick while the frame rasterises
        t = time.perf_counter()
        app.render_frame(overlap=tick)
        ctx.finish()
        overlapped.append((time.perf_counter() - t) * 1e3)
    print(f"demo at {width}x{height} (render_scale {app.renderer.render_scale}), {frames} frames after "
          f"warm-up, one fixed tick per frame:")

    def row(name: str, values: list[float]) -> str:
        return (f"  {name:<22s} mean {statistics.fmean(values):7.2f}  median {statistics.median(values):7.2f}  "
                f"best {min(values):7.2f} ms")

    print("  tick, then frame:")
    print(row("simulation tick", ticks))
    print(row("render frame", draws))
    print(row("whole frame", frame))
    print(f"    -> {1e3 / statistics.fmean(frame):5.1f} fps mean, {1e3 / statistics.median(frame):5.1f} fps median")
    print("  tick overlapped with the frame's rasterisation (how the demo runs):")
    print(row("simulation tick", overlapped_ticks))
    print(row("whole frame", overlapped))
    print(f"    -> {1e3 / statistics.fmean(overlapped):5.1f} fps mean, {1e3 / statistics.median(overlapped):5.1f} fps "
          f"median (target >= 30 fps; on a shared machine the median is the steadier figure)")
    dynamic = app.config.render.dynamic_resolution
    app.config.render.dynamic_resolution = False
    realtime_loop(app, ctx, frames)
    if dynamic:  # as the window runs the demo: the render scale follows the frame time ([render] dynamic_resolution)
        app.config.render.dynamic_resolution = True
        realtime_loop(app, ctx, frames + 30, dynamic=True)
        app.config.render.dynamic_resolution = False  # the breakdown below at the set scale
        app.renderer.resolution.reset()
    renderer.timer.enabled, renderer.timer.gpu = True, False  # breakdown: a GL finish after every pass
    renderer.timer.reset()
    for _ in range(frames // 2):
        app.step(1)
        app.render_frame()
    print("per-pass breakdown (each pass timed with a finish, so the sum exceeds the plain frame):")
    print(renderer.timer.report())
    # where the main thread blocks: no finish between passes; a pass that samples what queued passes draw
    # waits for the raster threads (llvmpipe), and neither side overlaps the other meanwhile
    renderer.timer.waits = True
    renderer.timer.reset()
    for _ in range(frames // 2):
        app.step(1)
        app.render_frame()
        ctx.finish()
    renderer.timer.enabled = renderer.timer.waits = False
    print(renderer.timer.report_waits(top=12))
    tick_by_system(app)


def tick_by_system(app: App, ticks: int = 240) -> None:
    """CPU time a tick of each system (this thread's ``time.thread_time``), over ``ticks`` ticks of the autoplay;
    the systems' sum is the tick the real-time loop repeats a few times a frame. The demo's smoke puffs come and
    go with the targets, so its figure is an average over ticks with none, one or two."""
    totals: dict[str, float] = {}
    originals = [(system, system.fn) for system in app.schedule.systems]
    for system, fn in originals:
        def timed(world, dt, fn=fn, name=system.name):
            start = time.thread_time()
            fn(world, dt)
            totals[name] = totals.get(name, 0.0) + time.thread_time() - start

        system.fn = timed
    start = time.thread_time()
    app.step(ticks)
    whole = time.thread_time() - start
    for system, fn in originals:
        system.fn = fn
    print(f"tick by system, CPU ms a tick over {ticks} ticks (whole tick {1e3 * whole / ticks:.2f} ms):")
    for name, total in sorted(totals.items(), key=lambda kv: -kv[1]):
        if total * 1e3 / ticks >= 0.01:
            print(f"  {name:<40s} {1e3 * total / ticks:7.3f} ms")


def _cpu_ns() -> tuple[int, int]:
    """(main thread, every other thread of this process) CPU time in ns, from /proc (Linux); (0, 0) elsewhere."""
    main, others = 0, 0
    try:
        for tid in os.listdir("/proc/self/task"):
            with open(f"/proc/self/task/{tid}/schedstat") as f:
                ns = int(f.read().split()[0])
            if int(tid) == os.getpid():
                main += ns
            else:
                others += ns
    except OSError:
        pass
    return main, others


def realtime_loop(app: App, ctx, frames: int, dynamic: bool = False) -> None:
    """The window's loop: ``advance`` with the previous frame's measured length (see the module docstring).
    ``dynamic``: with ``[render] dynamic_resolution`` on, the render scale each frame was drawn at is reported too
    (the first 30 frames let it settle and are not counted)."""
    ctx.finish()
    times, ticks, scales = [], [], []
    last = 1.0 / 60.0
    settle = 30 if dynamic else 0
    for _ in range(settle):
        t = time.perf_counter()
        app.advance(last)
        ctx.finish()
        last = time.perf_counter() - t
    frames -= settle
    cpu0, t0 = _cpu_ns(), time.perf_counter()
    for _ in range(frames):
        t = time.perf_counter()
        ticks.append(app.advance(last))
        ctx.finish()
        last = time.perf_counter() - t
        times.append(last * 1e3)
        scales.append(app.renderer.render_scale)
    wall, cpu1 = time.perf_counter() - t0, _cpu_ns()
    main_ms, other_ms = ((b - a) / 1e6 / frames for a, b in zip(cpu0, cpu1))
    if dynamic:
        shares = ", ".join(f"{scale:.2f}: {scales.count(scale) / len(scales):.0%}"
                           for scale in sorted(set(scales), reverse=True))
        print(f"  real-time loop with dynamic resolution (target {app.config.render.target_fps:g} fps, render "
              f"scale down to {app.config.render.min_render_scale:g}; after {settle} frames to settle), frames at "
              f"each scale: {shares}")
    else:
        print(f"  real-time loop (advance with the measured frame time, fixed step {app.dt * 1e3:.2f} ms; as the "
              f"window runs it; at the set render scale):")
    print(f"  {'frame':<22s} mean {statistics.fmean(times):7.2f}  median {statistics.median(times):7.2f}  "
          f"best {min(times):7.2f} ms, {statistics.fmean(ticks):.2f} ticks a frame")
    print(f"    -> {frames / wall:5.1f} fps (frames / wall time)")
    if main_ms or other_ms:
        print(f"  CPU a frame: main thread {main_ms:.1f} ms, rasteriser and other threads {other_ms:.1f} ms; "
              f"(sum) / 2 = {(main_ms + other_ms) / 2:.1f} ms is the floor on 2 cores, "
              f"{1e3 * wall / frames:.1f} ms measured")


if __name__ == "__main__":
    main()
