"""ToonSmokeVolume benchmark: the paper's workload (seeds/002 §4) beside the paper's figure.

Paper: Intel Core2 Duo 2.66 GHz, 32³ simulation grid, 64³ display grid, 1000 particles, isosurface every frame:
about 0.6 fps.  Here: the ``paper`` preset (the same grids and particle count, the sphere obstacle in the middle),
every phase of :data:`systems.toon_smoke.simulate.PHASES` plus marching cubes each step, timed one by one after a
warm-up that lets the smoke fill the volume.  Optionally (``--render``) the headless renderer draws every step too.

    .venv/bin/python bench/toon_smoke_bench.py [--preset paper] [--warmup 150] [--steps 300] [--render 640x480]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # the splat's small products: threads only add contention

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from components.toon_smoke import ToonSmokeVolumeConfig  # noqa: E402
from engine.spatial import Transform  # noqa: E402
from systems.toon_smoke import simulate  # noqa: E402

PAPER_FPS = 0.6
TARGET_RATIO = 50.0


def load_preset(name: str) -> ToonSmokeVolumeConfig:
    """A preset of configs/effects/toon_smoke/ by its name (``explosion``, or as a scene names it,
    ``toon_smoke/explosion``); an unknown name exits with the names there are."""
    import tomllib

    folder = ROOT / "configs" / "effects" / "toon_smoke"
    path = folder / f"{name.removeprefix('toon_smoke/')}.toml"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in folder.glob("*.toml")))
        raise SystemExit(f"--preset {name!r}: no {path.relative_to(ROOT)}; the presets are {known}")
    return ToonSmokeVolumeConfig.model_validate(tomllib.loads(path.read_text(encoding="utf-8")))


def run_phases(cfg: ToonSmokeVolumeConfig, warmup: int, steps: int, dt: float, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    state = simulate.new_state(cfg, rng)
    ctx = simulate.StepContext(None, 1, Transform(), cfg, state, dt, rng)
    names = [name for name, _ in simulate.PHASES] + ["marching cubes (isosurface)"]
    phases = list(simulate.PHASES) + [("marching cubes (isosurface)", lambda c: simulate.mesh_step(c.cfg, c.state))]
    wall = dict.fromkeys(names, 0.0)
    cpu = dict.fromkeys(names, 0.0)
    stats = {"divergence_before": [], "divergence_after": [], "iterations": [], "blobs": [], "triangles": []}
    for step in range(warmup + steps):
        measuring = step >= warmup
        for name, phase in phases:  # loop over phases, timing each
            w0, c0 = time.perf_counter(), time.process_time()
            phase(ctx)
            if measuring:
                wall[name] += time.perf_counter() - w0
                cpu[name] += time.process_time() - c0
        state.time += dt
        state.steps += 1
        if measuring:
            stats["divergence_before"].append(state.divergence_before)
            stats["divergence_after"].append(state.divergence_after)
            stats["iterations"].append(state.pressure_iterations_used)
            stats["blobs"].append(state.blob_count)
            stats["triangles"].append(len(state.mesh_faces))
    return {"wall": wall, "cpu": cpu, "stats": stats, "steps": steps, "state": state}


def run_rendered(preset: str, size: tuple[int, int], frames: int, warmup: int) -> float:
    """Frames per second of step + marching cubes + headless render at ``size`` (llvmpipe on this machine)."""
    import tempfile

    from engine.app import App
    from engine.render.frontend import create_headless_context
    from engine.render.renderer import Renderer

    scene = f"""
[scene]
name = "bench"
seed = 1
fixed_dt = 0.0333333
plugins = ["render", "toon_smoke"]
[[entities]]
name = "camera"
[entities.components.Transform]
[entities.components.Camera]
controller = "orbit"
target = [0.0, 0.3, 0.0]
distance = 5.5
yaw = 15.0
pitch = -6.0
[[entities]]
name = "smoke"
[entities.components.Transform]
[entities.components.ToonSmokeVolume]
preset = "toon_smoke/{preset}"
"""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.toml"
        path.write_text(scene, encoding="utf-8")
        app = App(path, configs_root=ROOT / "configs")
        renderer = Renderer(app, create_headless_context(), *size)
        app.step(warmup)
        app.render_frame()
        start = time.perf_counter()
        for _ in range(frames):
            app.step(1)
            app.render_frame()
        renderer.ctx.finish()
        elapsed = time.perf_counter() - start
        renderer.release()
    return frames / elapsed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--warmup", type=int, default=150, help="steps before measuring (smoke fills the volume)")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--render", default=None, help="also time step + render at WxH (headless), e.g. 640x480")
    args = parser.parse_args()

    cfg = load_preset(args.preset)
    dt = 1.0 / 30.0
    print(f"ToonSmokeVolume benchmark: preset '{args.preset}': simulation {list(cfg.simulation_resolution)}, display "
          f"{list(cfg.display_resolution)}, {cfg.particle_count} particles, obstacle r = {cfg.obstacle_radius} m, "
          f"Δt = {dt:.4f} s; warm-up {args.warmup} steps, measured {args.steps} steps")
    result = run_phases(cfg, args.warmup, args.steps, dt, args.seed)
    n = result["steps"]
    wall_total = sum(result["wall"].values())
    cpu_total = sum(result["cpu"].values())
    print(f"\n{'phase':<38s}{'wall ms/step':>14s}{'cpu ms/step':>14s}{'share':>8s}")
    for name in result["wall"]:
        w, c = result["wall"][name] / n * 1e3, result["cpu"][name] / n * 1e3
        print(f"{name:<38s}{w:14.2f}{c:14.2f}{100 * result['wall'][name] / wall_total:7.1f}%")
    print(f"{'total':<38s}{wall_total / n * 1e3:14.2f}{cpu_total / n * 1e3:14.2f}")

    steps_per_s = n / wall_total
    cpu_steps_per_s = n / cpu_total
    st = result["stats"]
    target = ""
    if args.preset == "paper":  # the target is for the paper's workload only
        met = "met" if steps_per_s >= TARGET_RATIO * PAPER_FPS else "NOT met"
        target = f", target ≥ {TARGET_RATIO:.0f}× = {TARGET_RATIO * PAPER_FPS:.0f} steps/s: {met}"
    print(f"\nsteps per second (wall clock, simulation + isosurface): {steps_per_s:7.1f}   "
          f"(paper: {PAPER_FPS} fps, ratio {steps_per_s / PAPER_FPS:6.1f}×{target})")
    print(f"steps per second (process CPU time):                     {cpu_steps_per_s:7.1f}   "
          f"(ratio {cpu_steps_per_s / PAPER_FPS:6.1f}×; the 2 cores are shared, CPU time is the steadier figure)")
    print(f"\nmax |∇·u| before projection (1/s): mean {np.mean(st['divergence_before']):.3g}; after: mean "
          f"{np.mean(st['divergence_after']):.3g}, worst {np.max(st['divergence_after']):.3g} "
          f"(worst after/before {np.max(np.array(st['divergence_after']) / np.array(st['divergence_before'])):.2g}, "
          f"tolerance {cfg.pressure_tolerance:g})")
    print(f"pressure solve: MGPCG iterations per step mean {np.mean(st['iterations']):.2f}, max "
          f"{np.max(st['iterations'])}")
    print(f"particles adding blobs per step: mean {np.mean(st['blobs']):.0f} of {cfg.particle_count}; isosurface "
          f"triangles per step: mean {np.mean(st['triangles']):.0f}, max {np.max(st['triangles'])}")
    if args.render:
        w, h = (int(v) for v in args.render.lower().split("x"))
        try:
            fps = run_rendered(args.preset, (w, h), min(args.steps, 120), args.warmup)
            print(f"\nwith rendering at {w}×{h} (headless llvmpipe): {fps:.1f} fps (paper {PAPER_FPS} fps, ratio "
                  f"{fps / PAPER_FPS:.1f}×)")
        except Exception as exc:  # the simulation figures above stand on their own
            print(f"\nrendered run skipped: {exc}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
