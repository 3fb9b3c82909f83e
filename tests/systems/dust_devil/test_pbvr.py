"""PBVR's three implementations (headless EGL): the scatter path as a compute shader (GL 4.3) or in the vertex
stage (GL 4.2 image stores) and the GL 3.3 slab path count, per pixel, the repeats whose opaque ensemble image
covers it, exactly as a numpy re-implementation of the same hashed pseudo-particles does (2.3, seeds/004)."""

from pathlib import Path

import numpy as np
import pytest

from engine.app import App
from engine.render.components import look_at, perspective
from systems.dust_devil.render import (BALL_OFFSETS, ball_offsets, extract_devils, frame_key, sample_indices,
                                       screen_rect)
from tests.render_utils import make_renderer
from tests.systems.dust_devil.helpers import scene_text
from tests.systems.dust_devil.test_render import camera

ROOT = Path(__file__).resolve().parents[3]
WIDTH, HEIGHT = 96, 72


def reference_counts(positions, view_proj, scene_depth, repeats, sub_particles, key, radius, point_size, seed):
    """Per pixel, the number of repeats r with a visible pseudo-particle's point on it (numpy, float64): sample
    r * K + k of particle i is entry sample_indices(...)[i, r K + k] of the scene seed's ball table."""
    n, samples = len(positions), repeats * sub_particles
    particle = np.repeat(np.arange(n), samples)
    sample = np.tile(np.arange(samples), n)
    table = ball_offsets(seed)[:, :3].astype(np.float64)
    offset = radius * table[sample_indices(n, samples, key).ravel()]
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


def coverage_counts(texture) -> np.ndarray:
    """Set bits per pixel of a coverage image (HEIGHT x words rows of uint32 words)."""
    words = np.frombuffer(texture.read(), np.uint32).reshape(-1, HEIGHT, WIDTH)
    return sum(np.unpackbits(w.view(np.uint8).reshape(HEIGHT, WIDTH, 4), axis=-1).sum(-1) for w in words)


class _AroundResolve:
    """The graph as the dust devil feature sees it, with the PBVR resolve's execute wrapped: the coverage
    counts are read just before the resolve and again after it (it zeroes the words it reads)."""

    def __init__(self, graph, out: dict) -> None:
        self._graph, self._out = graph, out

    def add_pass(self, name, setup, execute, side_effect=False):
        if ".pbvr_resolve." in name and self._out["scatter"]:
            coverage = name.replace(".pbvr_resolve.", ".coverage.")

            def wrapped(pc):
                self._out["counts"] = coverage_counts(pc.get(coverage))
                execute(pc)
                self._out["after"] = coverage_counts(pc.get(coverage))

            return self._graph.add_pass(name, setup, wrapped, side_effect=side_effect)
        return self._graph.add_pass(name, setup, execute, side_effect=side_effect)

    def __getattr__(self, item):
        return getattr(self._graph, item)


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
    out = {"scatter": scatter}
    add_passes = feature.add_passes
    try:
        for _ in range(earlier_frames):
            renderer.render(app.world)
        renderer.extract(app.world)
        feature.add_passes = lambda graph, view, data: add_passes(_AroundResolve(graph, out), view, data)
        graph = renderer.declare()
        view = renderer.views[0]
        devil = extract_devils(app.world)[0]
        assert feature.path == pbvr_path
        assert scatter != any(".pbvr_clear." in name for name in graph.compile().order)  # scatter: no clear pass

        def setup(b):
            if not scatter:
                b.read(f"dust_devil.{devil.entity}.accumulation.{view.name}")
            b.read(view.depth)

        def execute(pc):
            if not scatter:
                tex = pc.get(f"dust_devil.{devil.entity}.accumulation.{view.name}")
                out["counts"] = np.frombuffer(tex.read(), np.float16).reshape(HEIGHT, WIDTH, 4)[..., 3].astype(int)
            out["depth"] = np.frombuffer(pc.get(view.depth).read(), np.float32).reshape(HEIGHT, WIDTH)

        graph.add_pass("test.read_pbvr", setup, execute, side_effect=True)
        graph.execute()
        ref = reference_counts(devil.positions, view.view_proj, out["depth"], repeats, devil.sub_particles,
                               feature.frame_key, devil.radius, devil.point_size,
                               app.world.random.seed)
    finally:
        feature.add_passes = add_passes
        renderer.release()
        app.renderer = None
    if scatter:  # the resolve zeroed every word it read: the next frame starts from an empty image
        assert out["after"].sum() == 0
    return out["counts"], ref


@pytest.mark.parametrize("path, repeats, point_size", [("compute", 8, 2.0), ("compute", 40, 1.0),
                                                       ("compute", 6, 2.5), ("vertex", 8, 2.0), ("vertex", 40, 1.0),
                                                       ("vertex", 6, 2.5), ("slab", 8, 2.0)])
def test_each_repeat_counts_once_per_pixel_as_the_reference(tmp_path, gl_ctx, path, repeats, point_size):
    counts, ref = rendered_counts(tmp_path, path, repeats, f"{path}r{repeats}", point_size)
    covered = ref > 0
    assert covered.sum() >= 250 and ref.max() == repeats  # the dense core is covered by every repeat
    assert 0 < (ref < counts.max() - 1).sum()  # partly hidden by the terrain or sparse: not all pixels saturate
    assert counts.max() <= repeats
    # float32 on the GPU vs float64 here: a pseudo-particle on a pixel edge may land one pixel over
    assert np.abs(counts - ref).sum() <= 0.01 * ref.sum()
    assert (counts != ref).sum() <= 0.03 * covered.sum()


def test_the_slab_paths_final_picture_is_the_scatter_paths(tmp_path, gl_ctx):
    """The GL 3.3 slab path's resolve composites like the scatter path's: the same frame through both gives the
    same picture (the counts test above reads the slab's accumulation before its resolve, so a broken resolve
    went unseen), and the dust is in it (the picture differs from the frame without the dust devil)."""
    import numpy as np

    path = tmp_path / "slab.toml"
    path.write_text(scene_text(amplitude=4.0, position=(0.0, -2.0, 0.0), particle_count=400, prewarm_time=2.0,
                               repeats=8, drag_repeats=1, show_markers=False, point_size=2.0,
                               sub_particle_radius=0.8, grid_resolution=[16, 16, 16])
                    + camera(target_y=4.0, distance=18.0, pitch=-10.0), encoding="utf-8")
    pictures = {}
    for name in ("compute", "slab", "hidden"):
        app = App(path, strict=True, configs_root=ROOT / "configs")
        app.step(1)
        renderer = make_renderer(app, WIDTH, HEIGHT)
        try:
            feature = next(f for f in renderer.features if f.name == "dust_devil")
            feature.use_scatter(8)
            feature.scatter = feature.compute = name == "compute"
            if name == "hidden":
                from components.dust_devil import DustDevilState

                for entity, _ in app.world.query(DustDevilState):
                    app.world.commands.despawn(entity)
                app.world.commands.apply()
            app.render_frame()
            pictures[name] = np.asarray(renderer.read_image().convert("RGB"), np.int16)
        finally:
            renderer.release()
            app.renderer = None
    dust = np.abs(pictures["compute"] - pictures["hidden"]).max(axis=2) > 24
    assert dust.sum() > 200
    diff = np.abs(pictures["slab"] - pictures["compute"]).max(axis=2)
    assert (diff > 24).sum() <= 0.03 * dust.sum() and diff.mean() < 1.0


@pytest.mark.parametrize("pbvr_path, repeats", [("compute", 8), ("compute", 40), ("vertex", 8)])
def test_coverage_is_cleared_between_frames(tmp_path, gl_ctx, pbvr_path, repeats):
    """The third frame's counts are its own ensemble's: the coverage words are zeroed inside the cloud's
    rectangle (both words per pixel for R > 32) before every scatter."""
    counts, ref = rendered_counts(tmp_path, pbvr_path, repeats, f"clear_{pbvr_path}{repeats}", 1.0, earlier_frames=2)
    assert ref.sum() > 300
    assert np.abs(counts - ref).sum() <= 0.01 * ref.sum()


@pytest.mark.parametrize("seed", [1, 4, 12345])
def test_ball_offsets_are_uniform_in_the_unit_ball(seed):
    """The offset table (2.3: pseudo-particles uniform in the ball around a particle): inside the unit ball,
    ρ³ uniform on [0, 1] (mean 1/2; Kolmogorov-Smirnov), directions isotropic (mean 0, second moments I / 3 of
    E ρ² = 3/5); drawn from the scene's seed, the same bits every time."""
    table = ball_offsets(seed)
    assert table.shape == (BALL_OFFSETS, 4) and table.dtype == np.float32 and not table[:, 3].any()
    d = table[:, :3].astype(np.float64)
    cubed = np.sort(np.linalg.norm(d, axis=1) ** 3)
    n = len(cubed)
    assert cubed[-1] <= 1.0 + 1e-6
    assert abs(cubed.mean() - 0.5) < 4.0 * np.sqrt(1.0 / 12.0 / n)  # 4 sigma
    ks = max(np.abs(cubed - np.arange(1, n + 1) / n).max(), np.abs(cubed - np.arange(n) / n).max())
    assert ks < 1.63 / np.sqrt(n)  # KS at the 1 % level
    assert np.abs(d.mean(axis=0)).max() < 4.0 * np.sqrt(0.2 / n)  # E x = 0, var x = E ρ² / 3 = 1/5
    moments = d.T @ d / n  # E x x^T = I / 5
    assert np.abs(moments - 0.2 * np.eye(3)).max() < 0.03
    octants = np.bincount((d > 0.0) @ [1, 2, 4], minlength=8)
    assert ((octants - n / 8) ** 2 / (n / 8)).sum() < 20.3  # chi-square, 7 degrees of freedom, 0.5 %
    assert np.array_equal(ball_offsets(seed), table)
    assert not np.array_equal(ball_offsets(seed + 1), table)


@pytest.mark.parametrize("repeats, sub_particles", [(16, 2), (64, 16)])
def test_a_particles_samples_are_distinct_table_entries(repeats, sub_particles):
    """Per particle and frame, the R x K samples are R x K different table entries (independent draws, up to
    the largest R x K = 1024), starting at a hashed entry that is uniform over the table and new each frame."""
    samples = repeats * sub_particles
    for frame in (0, 1, 977):
        index = sample_indices(5000, samples, frame_key(frame))
        assert index.max() < BALL_OFFSETS
        assert all(len(np.unique(row)) == samples for row in index[:200])
        starts = np.bincount(index[:, 0], minlength=BALL_OFFSETS).reshape(16, -1).sum(axis=1)
        assert ((starts - 5000 / 16) ** 2 / (5000 / 16)).sum() < 37.7  # chi-square, 15 degrees, 0.1 %
    assert (sample_indices(5000, 1, frame_key(1)) != sample_indices(5000, 1, frame_key(2))).mean() > 0.99


def test_repeats_are_uncorrelated_and_uniform_in_the_ball():
    """The offsets drawn this frame over many particles: repeat r and r + 1 of a particle are uncorrelated, and
    pooled they are uniform in the ball (mean ρ³ = 1/2)."""
    table = ball_offsets(7)[:, :3].astype(np.float64)
    d = table[sample_indices(4000, 32, frame_key(3))]  # (particles, R K, 3) with K = 2
    first, second = d[:, 0], d[:, 2]  # sample 0 of repeats 0 and 1
    correlation = np.corrcoef(first.ravel(), second.ravel())[0, 1]
    # the pairs are (entry j, entry j + 2) of the table: at most 3 x 1024 independent coordinate pairs
    assert abs(correlation) < 4.0 / np.sqrt(3 * BALL_OFFSETS)
    assert abs((np.linalg.norm(d, axis=-1) ** 3).mean() - 0.5) < 0.02


@pytest.mark.parametrize("eye, spread, radius", [((0.0, 6.0, 25.0), 1.5, 0.8), ((0.0, 5.0, 6.0), 0.7, 0.6)])
def test_screen_rect_holds_every_pseudo_particle(eye, spread, radius):
    """The rectangle holds every pixel the reference covers, also for balls close to the camera and off axis
    (their images stretch outwards), and is smaller than the view."""
    rng = np.random.default_rng(3)
    positions = rng.normal(0.0, spread, (500, 3)).astype(np.float32) + [0.0, 5.0, 0.0]
    view_proj = (perspective(np.radians(50.0), WIDTH / HEIGHT, 0.1, 200.0) @ look_at(eye, (0, 5, 0))).astype(
        np.float32)
    rect = screen_rect(positions, view_proj, WIDTH, HEIGHT, radius=radius, point_size=2.0)
    ref = reference_counts(positions, view_proj, np.ones((HEIGHT, WIDTH)), 8, 2, frame_key(9), radius, 2.0, 1)
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
