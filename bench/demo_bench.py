"""Demo benchmark: frame time of the demo at 1280x720 headless (autoplay driving it), with the per-pass
breakdown from the profiler (CPU time with a GL finish per pass, which is exact on llvmpipe), and the
simulation tick time.  Target: >= 30 fps on llvmpipe.
"""

from __future__ import annotations

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
    print(f"demo at {width}x{height} (render_scale {app.config.render.render_scale}), {frames} frames after "
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
    renderer.timer.enabled, renderer.timer.gpu = True, False  # breakdown: a GL finish after every pass
    renderer.timer.totals.clear()
    renderer.timer.frames = 0
    for _ in range(frames // 2):
        app.step(1)
        app.render_frame()
    print("per-pass breakdown (each pass timed with a finish, so the sum exceeds the plain frame):")
    print(renderer.timer.report())


if __name__ == "__main__":
    main()
