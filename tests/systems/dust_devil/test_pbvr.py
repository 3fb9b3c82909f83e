"""PBVR's three implementations (headless EGL): the scatter path as a compute shader (GL 4.3) or in the vertex
stage (GL 4.2 image stores) and the GL 3.3 slab path count, per pixel, the repeats whose opaque ensemble image
covers it, exactly as a numpy re-implementation of the same hashed pseudo-particles does (2.3, seeds/004)."""

from pathlib import Path

import numpy as np
import pytest

from engine.app import App
from engine.render.components import look_at, perspective
from systems.dust_devil.render import extract_devils, screen_rect
from tests.render_utils import make_renderer
from tests.systems.dust_devil.helpers import scene_text
from tests.systems.dust_devil.test_render import camera

ROOT = Path(__file__).resolve().parents[3]
WIDTH, HEIGHT = 96, 72


def pcg3d(v: np.ndarray) -> np.ndarray:
    """shaders/pbvr_sample.glsl's hash on uint32 (N, 3) rows."""
    with np.errstate(over="ignore"):
        v = v.astype(np.uint32) * np.uint32(1664525) + np.uint32(1013904223)
        x, y, z = v[:, 0].copy(), v[:, 1].copy(), v[:, 2].copy()
        x += y * z
        y += z * x
        z += x * y
        x ^= x >> np.uint32(16)
        y ^= y >> np.uint32(16)
        z ^= z >> np.uint32(16)
        x += y * z
        y += z * x
        z += x * y
    return np.stack([x, y, z], axis=-1)


def reference_counts(positions, view_proj, scene_depth, repeats, sub_particles, seed, radius, point_size):
    """Per pixel, the number of repeats r with a visible pseudo-particle's point on it (numpy, float64)."""
    n, samples = len(positions), repeats * sub_particles
    particle = np.repeat(np.arange(n), samples)
    sample = np.tile(np.arange(samples), n)
    u = (pcg3d(np.stack([particle, sample, np.full_like(particle, seed)], -1)) >> np.uint32(8)) / 16777216.0
    z, phi = 2.0 * u[:, 0] - 1.0, 2.0 * np.pi * u[:, 1]
    s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    offset = radius * np.cbrt(u[:, 2])[:, None] * np.stack([s * np.cos(phi), z, s * np.sin(phi)], -1)
    world = positions[particle].astype(np.float64) + offset
    clip = np.c_[world, np.ones(len(world))] @ view_proj.astype(np.float64).T
    ndc = clip[:, :3] / clip[:, 3:]
    inside = (clip[:, 3] > 0) & (np.abs(ndc[:, 2]) <= 1.0)
    window = (ndc[:, :2] * 0.5 + 0.5) * [WIDTH, HEIGHT]
    depth = 0.5 * ndc[:, 2] + 0.5
    # pixels whose centres lie in the point's square [window - size/2, window + size/2)
    first = np.floor(window - 0.5 * point_size + 0.5).astype(int)
    last = np.floor(window + 0.5 * point_size + 0.5).astype(int)
    covered = np.zeros((repeats, HEIGHT, WIDTH), bool)
    side = int(np.ceil(point_size))
    for dy in range(side):
        for dx in range(side):
            x, y = first[:, 0] + dx, first[:, 1] + dy
            ok = inside & (x < last[:, 0]) & (y < last[:, 1]) & (x >= 0) & (x < WIDTH) & (y >= 0) & (y < HEIGHT)
            ok[ok] &= depth[ok] <= scene_depth[y[ok], x[ok]]
            covered[(sample // sub_particles)[ok], y[ok], x[ok]] = True
    return covered.sum(axis=0)


def rendered_counts(tmp_path, pbvr_path: str, repeats: int, name: str, point_size: float = 2.0,
                    earlier_frames: int = 0):
    """(counts per pixel, reference counts, R) of one frame drawn by the chosen PBVR path: 'compute', 'vertex'
    (the scatter in a compute shader or in the vertex stage) or 'slab'; after ``earlier_frames`` frames (other
    ensembles, whose coverage must not leak into this one)."""
    scatter = pbvr_path != "slab"
    path = tmp_path / f"{name}.toml"
    path.write_text(scene_text(amplitude=4.0, position=(0.0, -2.0, 0.0), particle_count=400, prewarm_time=2.0,
                               repeats=repeats, drag_repeats=1, show_markers=False, point_size=point_size,
                               sub_particle_radius=0.8, grid_resolution=[16, 16, 16])
                    + camera(target_y=4.0, distance=18.0, pitch=-10.0), encoding="utf-8")
    app = App(path, strict=True, configs_root=ROOT / "configs")
    app.step(1)
    renderer = make_renderer(app, WIDTH, HEIGHT)
    feature = next(f for f in renderer.features if f.name == "dust_devil")
    assert feature.use_scatter(repeats), "this context has no GL 4.2 image stores in the vertex stage"
    assert feature.path == "compute", "this context (llvmpipe: GL 4.5) takes the compute path by default"
    feature.scatter, feature.compute = scatter, pbvr_path == "compute"
    out = {}
    try:
        for _ in range(earlier_frames):
            renderer.render(app.world)
        renderer.extract(app.world)
        graph = renderer.declare()
        view = renderer.views[0]
        devil = extract_devils(app.world)[0]
        target = "coverage" if scatter else "accumulation"
        assert feature.path == pbvr_path

        def setup(b):
            b.read(f"dust_devil.{devil.entity}.{target}.{view.name}")
            b.read(view.depth)

        def execute(pc):
            tex = pc.get(f"dust_devil.{devil.entity}.{target}.{view.name}")
            if scatter:
                words = np.frombuffer(tex.read(), np.uint32).reshape(-1, HEIGHT, WIDTH)
                out["counts"] = sum(np.unpackbits(w.view(np.uint8).reshape(HEIGHT, WIDTH, 4), axis=-1).sum(-1)
                                    for w in words)
            else:
                out["counts"] = np.frombuffer(tex.read(), np.float16).reshape(HEIGHT, WIDTH, 4)[..., 3].astype(int)
            out["depth"] = np.frombuffer(pc.get(view.depth).read(), np.float32).reshape(HEIGHT, WIDTH)

        graph.add_pass("test.read_pbvr", setup, execute, side_effect=True)
        graph.execute()
        ref = reference_counts(devil.positions, view.view_proj, out["depth"], repeats, devil.sub_particles,
                               renderer.frame_index, devil.radius, devil.point_size)
    finally:
        renderer.release()
        app.renderer = None
    return out["counts"], ref


@pytest.mark.parametrize("path, repeats, point_size", [("compute", 8, 2.0), ("compute", 40, 1.0),
                                                       ("compute", 6, 2.5), ("vertex", 8, 2.0), ("vertex", 40, 1.0),
                                                       ("vertex", 6, 2.5), ("slab", 8, 2.0)])
def test_each_repeat_counts_once_per_pixel_as_the_reference(tmp_path, gl_ctx, path, repeats, point_size):
    counts, ref = rendered_counts(tmp_path, path, repeats, f"{path}r{repeats}", point_size)
    covered = ref > 0
    assert covered.sum() > 300 and ref.max() == repeats  # the dense core is covered by every repeat
    assert 0 < (ref < counts.max() - 1).sum()  # partly hidden by the terrain or sparse: not all pixels saturate
    assert counts.max() <= repeats
    # float32 on the GPU vs float64 here: a pseudo-particle on a pixel edge may land one pixel over
    assert np.abs(counts - ref).sum() <= 0.01 * ref.sum()
    assert (counts != ref).sum() <= 0.03 * covered.sum()


@pytest.mark.parametrize("pbvr_path, repeats", [("compute", 8), ("compute", 40), ("vertex", 8)])
def test_coverage_is_cleared_between_frames(tmp_path, gl_ctx, pbvr_path, repeats):
    """The third frame's counts are its own ensemble's: the coverage words are zeroed inside the cloud's
    rectangle (both words per pixel for R > 32) before every scatter."""
    counts, ref = rendered_counts(tmp_path, pbvr_path, repeats, f"clear_{pbvr_path}{repeats}", 1.0, earlier_frames=2)
    assert ref.sum() > 300
    assert np.abs(counts - ref).sum() <= 0.01 * ref.sum()


@pytest.mark.parametrize("eye, spread, radius", [((0.0, 6.0, 25.0), 1.5, 0.8), ((0.0, 5.0, 6.0), 0.7, 0.6)])
def test_screen_rect_holds_every_pseudo_particle(eye, spread, radius):
    """The rectangle holds every pixel the reference covers, also for balls close to the camera and off axis
    (their images stretch outwards), and is smaller than the view."""
    rng = np.random.default_rng(3)
    positions = rng.normal(0.0, spread, (500, 3)).astype(np.float32) + [0.0, 5.0, 0.0]
    view_proj = (perspective(np.radians(50.0), WIDTH / HEIGHT, 0.1, 200.0) @ look_at(eye, (0, 5, 0))).astype(
        np.float32)
    rect = screen_rect(positions, view_proj, WIDTH, HEIGHT, radius=radius, point_size=2.0)
    ref = reference_counts(positions, view_proj, np.ones((HEIGHT, WIDTH)), 8, 2, 9, radius, 2.0)
    ys, xs = np.nonzero(ref)
    x, y, w, h = rect
    assert len(xs) and x <= xs.min() and xs.max() < x + w and y <= ys.min() and ys.max() < y + h
    assert w * h < WIDTH * HEIGHT


def test_screen_rect_whole_view_or_none():
    positions = np.array([[0.0, 5.0, 0.0], [1.0, 6.0, 0.0]], np.float32)
    view_proj = (perspective(np.radians(50.0), WIDTH / HEIGHT, 0.1, 200.0) @ look_at((0, 6, 25), (0, 5, 0))).astype(
        np.float32)
    assert screen_rect(np.r_[positions, [[0.0, 6.0, 25.3]]], view_proj, WIDTH, HEIGHT, 0.8, 2.0) == (
        0, 0, WIDTH, HEIGHT)  # a ball reaching the camera plane: the whole view
    assert screen_rect(positions + [500.0, 0.0, 0.0], view_proj, WIDTH, HEIGHT, 0.8, 2.0) is None  # off screen
    assert screen_rect(np.zeros((0, 3), np.float32), view_proj, WIDTH, HEIGHT, 0.8, 2.0) is None
