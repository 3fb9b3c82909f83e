"""Render benchmark: frame time of the sandbox scene at 1280x720 headless, and of N instanced lit boxes.

Measures the full frame (render-extract + graph execute + ctx.finish) over many frames after a warm-up
and prints the mean and the 95th percentile.  On machines without a GPU this is Mesa llvmpipe.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from engine.app import App  # noqa: E402
from engine.render.components import CameraConfig, MeshConfig, build_camera  # noqa: E402
from engine.render.frontend import create_headless_context  # noqa: E402
from engine.render.renderer import Renderer  # noqa: E402
from engine.registry import BuildContext  # noqa: E402
from engine.spatial import Transform  # noqa: E402


def measure(app: App, ctx, width: int, height: int, frames: int) -> tuple[float, float]:
    renderer = Renderer(app, ctx, width, height)
    for _ in range(3):
        app.step(1)
        app.render_frame()
    ctx.finish()
    times = []
    for _ in range(frames):
        app.step(1)
        t0 = time.perf_counter()
        app.render_frame()
        ctx.finish()
        times.append((time.perf_counter() - t0) * 1e3)
    renderer.release()
    app.renderer = None
    times.sort()
    return statistics.fmean(times), times[int(0.95 * (len(times) - 1))]


def boxes_app(n: int) -> App:
    app = App()
    w = app.world
    side = int(np.ceil(np.sqrt(n)))
    rng = np.random.default_rng(0)
    for i in range(n):
        x, z = (i % side - side / 2) * 1.5, (i // side - side / 2) * 1.5
        t = Transform(position=np.array([x, 0.5, z]), scale=np.full(3, 0.8))
        w.spawn(t, MeshConfig(shape="box", color=[float(c) for c in rng.uniform(0.2, 0.9, 3)]))
    cam = w.spawn(Transform())
    cfg = CameraConfig(controller="orbit", distance=side * 1.2, pitch=-35.0, far=2000.0)
    w.add(cam, build_camera(cfg, BuildContext(w, cam, "camera", "", None)))
    return app


def main() -> None:
    ctx = create_headless_context()
    print(f"GL renderer: {ctx.info['GL_RENDERER']}")
    print(f"{'case':<36s}{'size':>11s}{'mean ms':>10s}{'p95 ms':>10s}{'fps':>8s}")
    mean, p95 = measure(App("configs/scenes/sandbox.toml"), ctx, 1280, 720, 30)
    print(f"{'sandbox scene':<36s}{'1280x720':>11s}{mean:>10.2f}{p95:>10.2f}{1e3 / mean:>8.1f}")
    for n in (1000, 10000):
        mean, p95 = measure(boxes_app(n), ctx, 1280, 720, 20)
        print(f"{f'{n} instanced lit boxes':<36s}{'1280x720':>11s}{mean:>10.2f}{p95:>10.2f}{1e3 / mean:>8.1f}")


if __name__ == "__main__":
    main()
