"""Chunked terrain with a level of detail per view: geometry, level selection, culling, and no cracks on screen."""

import numpy as np
from engine.app import App
from engine.heightfield import HeightField
from engine.render import passes
from engine.render.terrain import CHUNK, build_terrain_chunks, draw_ranges, select_levels
from tests.render_utils import make_renderer, render_app

SCENE = """
[scene]
name = "terrain-lod"
seed = 3

[render]
width = 160
height = 120
sky_top = [1.0, 0.0, 1.0]
sky_horizon = [1.0, 0.0, 1.0]
fog_density = 0.0

[[entities]]
name = "ground"
[entities.components.Transform]
[entities.components.Terrain]
size_exponent = 6
spacing = 1.0
amplitude = 8.0
roughness = 0.6

[[entities]]
name = "camera"
[entities.components.Transform]
[entities.components.Camera]
controller = "orbit"
target = [0.0, 0.0, 0.0]
distance = 38.0
yaw = 30.0
pitch = -40.0
"""


def bumpy_field(n: int = 65, seed: int = 1) -> HeightField:
    heights = np.random.default_rng(seed).normal(0.0, 1.0, (n, n)).cumsum(axis=0).cumsum(axis=1) * 0.05
    return HeightField(heights, spacing=1.0, origin=np.array([-(n - 1) / 2, -(n - 1) / 2]))


def test_level_zero_holds_every_grid_triangle_and_levels_halve_the_lines():
    field = bumpy_field()
    mesh = build_terrain_chunks(field)
    quads = (field.heights.shape[0] - 1) * (field.heights.shape[1] - 1)
    chunks_per_side = (field.heights.shape[0] - 1) // CHUNK
    assert mesh.chunks == chunks_per_side**2
    assert mesh.levels == int(np.log2(CHUNK)) + 1
    # level 0 without skirts: exactly the 2 triangles per grid quad, once each
    surface = []
    for k in range(mesh.chunks):
        idx = mesh.indices[mesh.first[0, k]:mesh.first[0, k] + mesh.count[0, k]].reshape(-1, 3)
        surface.append(idx[(idx < field.heights.size).all(axis=1)])
    tris = np.concatenate(surface)
    assert len(tris) == 2 * quads
    assert len({tuple(sorted(t)) for t in tris.tolist()}) == 2 * quads
    # each level down has about a quarter of the triangles of the one above
    totals = mesh.count.sum(axis=1)
    assert all(totals[i + 1] < totals[i] / 2 for i in range(mesh.levels - 2))
    # errors grow with the level and are zero at level 0
    assert np.all(mesh.error[0] == 0) and np.all(np.diff(mesh.error, axis=0) >= 0) and mesh.error[-1].max() > 0


def test_a_flat_field_has_no_error_so_distant_chunks_use_the_coarsest_level():
    field = HeightField(np.zeros((65, 65)), spacing=1.0)
    mesh = build_terrain_chunks(field)
    assert np.all(mesh.error == 0)
    eye = np.array([32.0, 300.0, 32.0])
    levels = _levels(mesh, eye, target=(32.0, 0.0, 31.0), detail=2.0)
    assert np.all(levels == mesh.levels - 1)


def _levels(mesh, eye, target, detail, ortho=False, height=240):
    from engine.render.components import look_at

    view = look_at(np.asarray(eye, float), np.asarray(target, float))
    f = 1.0 / np.tan(np.radians(30.0))
    near, far = 0.1, 1000.0
    proj = np.zeros((4, 4))
    if ortho:
        proj[0, 0], proj[1, 1], proj[2, 2], proj[2, 3], proj[3, 3] = 1 / 40, 1 / 40, -2 / (far - near), -(far + near) / (far - near), 1
    else:
        proj[0, 0], proj[1, 1] = f, f
        proj[2, 2], proj[2, 3], proj[3, 2] = (far + near) / (near - far), 2 * far * near / (near - far), -1.0
    return select_levels(mesh, np.eye(4), proj @ view, proj, np.asarray(eye, float), height, ortho, detail)


def test_chunks_behind_the_camera_are_culled_and_far_chunks_are_coarser():
    field = bumpy_field(129, seed=4)
    mesh = build_terrain_chunks(field)
    eye = np.array([0.0, 6.0, 0.0])
    levels = _levels(mesh, eye, target=(0.0, 4.0, -50.0), detail=2.0)  # looking towards -z from the centre
    centres = (mesh.box_min + mesh.box_max) / 2
    behind = centres[:, 2] > CHUNK * 1.5  # well behind the eye
    assert np.all(levels[behind] == -1)
    visible = levels >= 0
    assert visible.sum() >= 4
    distance = np.linalg.norm(centres - eye, axis=1)
    near_chunk = np.argmin(np.where(visible, distance, np.inf))
    far_chunk = np.argmax(np.where(visible, distance, -np.inf))
    assert levels[near_chunk] == 0 and levels[far_chunk] > levels[near_chunk]
    full = _levels(mesh, eye, target=(0.0, 4.0, -50.0), detail=0.0)
    assert np.all(full[visible] == 0) and np.all(full[~visible] == -1)


def test_draw_ranges_merge_neighbouring_chunks_of_one_level():
    mesh = build_terrain_chunks(bumpy_field())
    everything = draw_ranges(mesh, np.zeros(mesh.chunks, np.int64))
    assert everything == [(0, int(mesh.count[0].sum()))]
    split = np.zeros(mesh.chunks, np.int64)
    split[1] = 2
    ranges = draw_ranges(mesh, split)
    assert sum(c for _, c in ranges) == mesh.count[0].sum() - mesh.count[0, 1] + mesh.count[2, 1]
    assert draw_ranges(mesh, np.full(mesh.chunks, -1)) == []


def _sky(image) -> np.ndarray:
    """Where the (magenta) sky shows in the lower half of the picture (the ground in front of the camera; the
    hill tops above may legitimately change their outline with the level)."""
    px = np.asarray(image, np.int16)[image.height // 2:]
    return (px[..., 0] > 180) & (px[..., 1] < 90) & (px[..., 2] > 180)


def _render_checkerboard(tmp_path, monkeypatch, skirts: bool, coarse: bool = True):
    scene = tmp_path / "terrain_lod.toml"
    scene.write_text(SCENE)

    def checkerboard(mesh, *args, **kwargs):
        side = int(round(np.sqrt(mesh.chunks)))
        i, j = np.divmod(np.arange(mesh.chunks), side)
        return np.where(((i + j) % 2 == 0) | (not coarse), 0, mesh.levels - 1)

    def build(field):
        mesh = build_terrain_chunks(field)
        if not skirts:
            mesh.vertices[:, 6] = 0.0
        return mesh

    monkeypatch.setattr(passes, "select_levels", checkerboard)
    monkeypatch.setattr(passes, "build_terrain_chunks", build)
    app = App(scene)
    make_renderer(app, 320, 240)
    return render_app(app, frames=1)


def test_skirts_hide_the_cracks_between_levels(tmp_path, monkeypatch):
    """Neighbouring chunks at the finest and the coarsest level: without skirts the sky shows through the
    seams (so the check can fail); with them the ground is closed."""
    closed = _sky(_render_checkerboard(tmp_path, monkeypatch, skirts=True, coarse=False))  # one level: no seams
    cracked = _sky(_render_checkerboard(tmp_path, monkeypatch, skirts=False)) & ~closed
    assert cracked.sum() > 20
    assert (_sky(_render_checkerboard(tmp_path, monkeypatch, skirts=True)) & ~closed).sum() == 0


def test_a_distant_view_draws_far_fewer_triangles_with_lod(tmp_path):
    triangles = {}
    for lod_pixels in (0.0, 2.0):
        scene = tmp_path / f"terrain_lod_{lod_pixels}.toml"
        scene.write_text(SCENE.replace("roughness = 0.6", f"roughness = 0.6\nlod_pixels = {lod_pixels}")
                         .replace("distance = 38.0", "distance = 150.0"))
        app = App(scene)
        renderer = make_renderer(app, 320, 240)
        feature = next(f for f in renderer.features if isinstance(f, passes.TerrainFeature))
        render_app(app, frames=1)
        triangles[lod_pixels] = feature.last_triangles["view0"]
    assert triangles[0.0] >= 2 * 64 * 64  # the whole field is in view at full detail
    assert 0 < triangles[2.0] < 0.5 * triangles[0.0]


# ------------------------------------------------------------------ baked shading
def test_shade_texels_are_the_lit_albedo_of_each_grid_point():
    from engine.render.terrain import shade_texels

    sun = np.array([0.0, 0.6, 0.8])
    kw = dict(sun_dir=sun, sun_color=(1.0, 0.9, 0.8), ambient=0.5, sky_top=(0.2, 0.4, 0.8), sky_horizon=(0.6, 0.7, 0.9))
    flat = shade_texels(HeightField(np.zeros((5, 5)), spacing=1.0), np.eye(4), [(0.5, 0.4, 0.3), (1, 1, 1)], **kw)
    # normal up: Lambert 0.6, hemisphere all sky_top; height range empty: the ramp's first colour, no rock darkening
    expected = np.array([0.5, 0.4, 0.3]) * (np.array([1.0, 0.9, 0.8]) * 0.6 + np.array([0.2, 0.4, 0.8]) * 0.5)
    assert flat.shape == (5, 5, 4) and np.allclose(flat[..., :3], expected, atol=1e-6) and np.all(flat[..., 3] == 1)

    # a 45° slope facing +x (h = -x): normal (1, 1, 0)/√2, rock-darkened by 30 %, the ramp's middle colour at mid-height
    x = np.arange(5.0)
    slope = HeightField(np.tile(-x, (5, 1)), spacing=1.0)
    texels = shade_texels(slope, np.eye(4), [(0.0, 0.0, 0.0), (0.4, 0.4, 0.4), (0.8, 0.8, 0.8)], **kw)
    n = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    t = (n[1] - 0.55) / 0.3
    rock = 0.7 + 0.3 * t * t * (3 - 2 * t)  # smoothstep(0.55, 0.85, n.y)
    hemi = (0.35 * np.array([0.6, 0.7, 0.9]) + (np.array([0.2, 0.4, 0.8]) - 0.35 * np.array([0.6, 0.7, 0.9]))
            * (0.5 * n[1] + 0.5)) * 0.5
    light = np.array([1.0, 0.9, 0.8]) * max(n @ sun, 0.0) + hemi
    assert np.allclose(texels[2, 2, :3], 0.4 * rock * light, atol=1e-6)  # middle of the slope: t = 0.5


def test_the_shade_texture_is_baked_once_and_again_when_the_light_changes(tmp_path):
    scene = tmp_path / "terrain.toml"
    scene.write_text(SCENE)
    app = App(scene)
    renderer = make_renderer(app, 160, 120)
    feature = next(f for f in renderer.features if isinstance(f, passes.TerrainFeature))
    first = None
    for frame in range(5):
        if frame == 3:
            renderer.sun_direction = np.array([0.0, 1.0, 0.0], np.float32)
        app.step(1)
        app.render_frame()
        if frame == 0:
            first = np.asarray(renderer.read_image(), np.float64)
        assert feature.bakes == (1 if frame < 3 else 2)
    assert np.abs(np.asarray(renderer.read_image(), np.float64) - first).mean() > 1.0  # the new light shows
    renderer.release()


def test_coarse_levels_keep_the_lighting_detail_of_the_full_grid(tmp_path, monkeypatch):
    """Straight down in an orthographic view, a chunk's level moves no pixel: with the light baked per grid
    point, the coarsest level looks like the full grid (per-vertex lighting would lose every bump between the
    coarse vertices)."""
    top = SCENE.replace('controller = "orbit"', 'projection = "orthographic"\northo_height = 70.0\ncontroller = "top"')
    top = top.replace('sky_top = [1.0, 0.0, 1.0]', 'sky_top = [0.2, 0.4, 0.8]')
    scene = tmp_path / "terrain_top.toml"
    scene.write_text(top.replace("distance = 38.0", "distance = 60.0"))
    images = {}
    for level in ("fine", "coarse"):
        monkeypatch.setattr(passes, "select_levels",
                            lambda mesh, *a, level=level, **k: np.full(mesh.chunks, 0 if level == "fine" else mesh.levels - 1))
        app = App(scene)
        make_renderer(app, 160, 120)
        images[level] = np.asarray(render_app(app, frames=1), np.float64)[..., :3]
    fine, coarse = images["fine"], images["coarse"]
    assert fine.std() > 5.0  # the bumps show
    assert np.abs(fine - coarse).mean() < 3.0  # the specular term, per vertex, differs a little
    assert _detail_correlation(fine, coarse) > 0.9


def _detail_correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Correlation of the fine detail (the image minus its 9 x 9 box blur) of two grey images."""
    def detail(img):
        g = img.mean(axis=-1)
        pad = np.pad(g, 4, mode="edge")
        blur = sum(pad[i:i + g.shape[0], j:j + g.shape[1]] for i in range(9) for j in range(9)) / 81.0
        return (g - blur)[8:-8, 8:-8].ravel()
    return float(np.corrcoef(detail(a), detail(b))[0, 1])


def test_skirts_hang_as_deep_as_the_largest_crack_of_their_edge():
    from engine.render.terrain import skirt_depths

    h = np.zeros((33, 33))
    h[16, 5] = 3.0  # a spike on the interior row line 16, inside the first chunk column [0, 16]
    depth = skirt_depths(h, np.array([0, 16]), np.array([0, 16]), levels=5, margin=0.1)
    # level 1 already skips column 5: the coarse edge misses the spike by its full height
    assert np.allclose(depth[16, :17], 3.1) and np.allclose(depth[16, 17:], 0.1)
    assert np.allclose(depth[:, 16], 0.1 + 3.0 * (np.arange(33) == 16))  # the corner vertex takes the deeper edge
    assert depth[5, 5] == 0.0  # not on an interior line: no skirt
    mesh = build_terrain_chunks(HeightField(h, spacing=1.0))
    assert np.isclose(mesh.vertices[:, 6].max(), 3.0 + 0.1, atol=1e-6)  # was the field's whole height range + 1


def test_full_detail_chunks_shaded_per_vertex_look_like_the_per_pixel_fetch(tmp_path, monkeypatch):
    """Full-detail chunks read the baked light once per vertex (their vertices are the grid points) and
    interpolate the colour; the picture matches the per-pixel texture fetch up to rounding (the fetch
    interpolates the encoded light, Gouraud the final colour), so the texel a vertex reads is the right one."""
    scene = tmp_path / "terrain_gouraud.toml"
    scene.write_text(SCENE.replace('sky_top = [1.0, 0.0, 1.0]', 'sky_top = [0.2, 0.4, 0.8]'))
    monkeypatch.setattr(passes, "select_levels", lambda mesh, *a, **k: np.zeros(mesh.chunks, np.int64))
    images, triangles = {}, {}
    for vertex_shade in (False, True):
        app = App(scene)
        renderer = make_renderer(app, 160, 120)
        feature = next(f for f in renderer.features if isinstance(f, passes.TerrainFeature))
        feature.vertex_shade = vertex_shade
        images[vertex_shade] = np.asarray(render_app(app, frames=1), np.float64)[..., :3]
        triangles[vertex_shade] = feature.last_triangles["view0"]
    per_pixel, per_vertex = images[False], images[True]
    assert triangles[True] == triangles[False] >= 2 * 64 * 64 * 0.5  # the same full-detail geometry
    assert per_pixel.std() > 5.0  # the bumps show
    diff = np.abs(per_pixel - per_vertex)
    assert diff.mean() < 1.5  # measured 0.74 (one texel off: 4.8)
    assert _detail_correlation(per_pixel, per_vertex) > 0.95
