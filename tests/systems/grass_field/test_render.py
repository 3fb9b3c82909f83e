"""Headless rendering: golden images near and far, the LOD cache (bakes counted, disk cache), the band,
the debug view, the presets, and that rendering leaves the simulation state alone."""

from __future__ import annotations

import numpy as np
import pytest

from components.grass_field import GrassFieldState
from systems.grass_field.impostor import ATLAS_MIP_LEVELS
from engine.app import App
from tests.render_utils import (assert_golden, ground_of_pixels, make_renderer, render_app, rendered, respawn,
                                world_pixel)
from tests.systems.grass_field.helpers import scene_text, write_scene

SMALL = 'preset = "grass_field/paper"\nplants_per_cell = 16\ncell_variants = 3\nplant_variants = 4\n'
DENSE = SMALL.replace("plants_per_cell = 16", "plants_per_cell = 64")  # 64 plants a cell


def _camera(position, yaw=0.0, pitch=-8.0, far=4000.0) -> str:
    return (f"[entities.components.Transform]\nposition = {list(position)}\nrotation = [{yaw}, {pitch}, 0.0]\n"
            f'[entities.components.Camera]\ncontroller = "none"\nfov = 50.0\nnear = 0.5\nfar = {far}\n')


def _app(tmp_path, grass: str, camera: str, terrain: bool = True, name: str = "scene.toml") -> App:
    return App(write_scene(tmp_path, scene_text(grass, camera, terrain=terrain), name))


def _feature(app):
    return next(f for f in app.renderer.features if f.name == "grass_field")


def _gpu(app):
    """The first field's GL side (FieldGpu)."""
    return next(iter(_feature(app).fields.values()))


def _plan(app):
    """The first (field, view)'s last frame plan."""
    return next(iter(_feature(app).plans.values()))


def test_golden_near(tmp_path):
    app = _app(tmp_path, SMALL + "grid_x = 6\ngrid_z = 6\n", _camera((0.0, 24.0, 40.0), pitch=-22.0))
    image = render_app(app, 160, 120, frames=1)
    assert_golden(image, "grass_field_near")


def test_golden_far(tmp_path):
    app = _app(tmp_path, SMALL + "grid_x = 24\ngrid_z = 24\n", _camera((0.0, 60.0, 1150.0), pitch=-4.0))
    image = render_app(app, 160, 120, frames=1)
    assert_golden(image, "grass_field_far")


def test_lod_cache_bakes_each_view_once_and_reuses_it(tmp_path):
    grass = SMALL + f"grid_x = 16\ngrid_z = 16\ndisk_cache = true\ncache_dir = '{tmp_path / 'cache'}'\n"
    camera = _camera((0.0, 40.0, 700.0), pitch=-5.0)
    app = _app(tmp_path, grass, camera)
    with rendered(app, 96, 72) as renderer:
        gpu = _gpu(app)
        assert gpu.baked_views == 3 * 12  # every view of every cell layout, once
        assert gpu.atlas is not None and gpu.layout.tiles == 36
        plan = _plan(app)
        assert len(plan.impostor_cells) > 0
        for _ in range(3):
            app.step(1)
            app.render_frame()
        assert gpu.baked_views == 36  # reused across frames
        app.restore(app.snapshot())  # restored copies of the state draw the same field: no rebake
        app.render_frame()
        assert _gpu(app) is gpu and gpu.baked_views == 36
        assert gpu.draw_calls <= 8  # instanced: a handful of draw calls, not one per cell or plant
        assert gpu.disk_path is not None and gpu.disk_path.is_file()
    again = _app(tmp_path, grass, camera, name="again.toml")
    renderer = make_renderer(again, 96, 72)
    try:
        again.step(1)
        again.render_frame()
        gpu = next(iter(_feature(again).fields.values()))
        assert gpu.loaded_from_disk and gpu.baked_views == 0  # a restart skips baking
    finally:
        renderer.release()
        again.renderer = None


def test_band_is_baked_and_drawn_beyond_the_distance(tmp_path):
    app = _app(tmp_path, SMALL + "grid_x = 24\ngrid_z = 24\nband_cache_cells = 2\n",
               _camera((0.0, 40.0, 0.0), pitch=-3.0))
    with rendered(app, 96, 72) as renderer:
        feature = _feature(app)
        plan = next(iter(feature.plans.values()))
        gpu = next(iter(feature.fields.values()))
        assert (plan.levels == 5).sum() > 50 and plan.primitives[5] > 0
        assert 1 <= gpu.band_bakes <= 2 and len(gpu.band_entries) <= 2
        bakes = gpu.band_bakes
        app.render_frame()
        assert gpu.band_bakes == bakes  # the viewer's cell did not change: no new bake


def _clarity_by_depth(tmp_path, grass: str, camera: str, name: str) -> np.ndarray:
    """How much of the grass's own colour survives the fog (1 clear, 0 all fog) in the far, middle and near
    thirds of the rows the grass covers: the frame rendered without fog, with the scene's fog and with a fog
    so dense that every grass pixel is the horizon colour, compared per pixel after the tone map."""
    frames = []
    for density in (0.0, 0.0005, 1.0):
        text = scene_text(grass, camera, terrain=False).replace("fog_density = 0.0005", f"fog_density = {density}")
        app = App(write_scene(tmp_path, text, f"{name}_{density}.toml"))
        frames.append(np.asarray(render_app(app, 160, 120), np.float64))
    clear, fogged, horizon = frames
    covered = np.abs(clear - horizon).max(axis=2) > 40
    clarity = np.linalg.norm(fogged - horizon, axis=2) / np.maximum(np.linalg.norm(clear - horizon, axis=2), 1e-9)
    rows = np.flatnonzero(covered.any(axis=1))
    thirds = np.array_split(np.arange(rows[0], rows[-1] + 1), 3)
    return np.array([clarity[t][covered[t]].mean() for t in thirds])


def test_the_band_is_fogged_at_the_distance_of_its_grass(tmp_path):
    """Only cells beyond the merge distance grow grass (the rest is bare), seen from 400 up: far grass shows
    higher in the picture.  The band's images are fogged per texel at their grass's distance, as the same cells
    drawn as level-4 rectangles where they stand (fog per corner); fogging the band at its own distance (800)
    made far grass as clear as near grass (clarity 0.29 in every third, the rectangles 0.10 to 0.22)."""
    grass = SMALL + "grid_x = 40\ngrid_z = 40\nbare_areas = [[-850.0, -850.0, 850.0, 850.0]]\n"
    camera = _camera((0.0, 400.0, 0.0), pitch=-18.0, far=5000.0)
    band = _clarity_by_depth(tmp_path, grass, camera, "band")
    rectangles = _clarity_by_depth(tmp_path, grass + "max_level = 4\n", camera, "rectangles")
    assert rectangles[0] < rectangles[2] - 0.08  # the reference: far thirds foggier
    assert np.abs(band - rectangles).max() < 0.03, (band, rectangles)


def test_bands_are_prefetched_ahead_of_the_viewer_and_the_height_step_has_hysteresis(tmp_path):
    from dataclasses import replace

    app = _app(tmp_path, SMALL + "grid_x = 24\ngrid_z = 24\nband_cache_cells = 9\n",
               _camera((0.0, 40.0, 0.0), pitch=-3.0))
    with rendered(app, 96, 72) as renderer:
        gpu = _gpu(app)
        placed = gpu.data.placed
        cell = int(placed.cell_of(np.array([0.0, 0.0])))
        base = placed.cell_centre[cell]
        from systems.grass_field.lod import CameraInput

        def at(x, z, y=None):
            return CameraInput(position=np.array([x, base[1] + 40.0 if y is None else y, z]),
                               forward=np.array([1.0, 0.0, 0.0]), fov_x=1.0, width=96)

        gpu.band_entries.clear()
        gpu._band_eyes.clear()
        gpu._band_levels.clear()
        gpu.ensure_band(cell, at(base[0], base[2]))
        gpu.ensure_band(cell, at(base[0], base[2]))  # standing still: nothing baked ahead
        assert [k[0] for k in gpu.band_entries] == [cell]
        step = float(placed.cell_centre[1, 0] - placed.cell_centre[0, 0])
        gpu.ensure_band(cell, at(base[0] + 0.1 * step, base[2]))  # moving along +x: the +x neighbour next
        assert [k[0] for k in gpu.band_entries] == [cell + 1, cell]
        # the eye bobbing a fifth of a step around a step boundary keeps the step in use: no re-bake
        bakes, half = gpu.band_bakes, 0.5 * gpu.data.plant_height
        level = gpu._band_levels[None]
        for dy in (0.2, -0.2, 0.2, -0.2):
            gpu.ensure_band(cell, at(base[0] + 0.1 * step, base[2], base[1] + (level + 0.5) * half + dy * half))
        assert gpu.band_bakes == bakes
        # two still views in one cell, apart and three height steps apart, drawn alternately: each keeps its own
        # step and its own last position, so after their first bakes nothing more is baked (sharing them, each
        # frame would see the viewer jump between the two and bake neighbours "ahead" of that jump)
        high = base[1] + (level + 3.0) * half
        gpu.ensure_band(cell, at(base[0] + 0.1 * step, base[2]))
        gpu.ensure_band(cell, at(base[0] - 0.3 * step, base[2] + 0.2 * step, high), viewer="high")
        bakes = gpu.band_bakes
        for _ in range(3):
            gpu.ensure_band(cell, at(base[0] + 0.1 * step, base[2]))
            gpu.ensure_band(cell, at(base[0] - 0.3 * step, base[2] + 0.2 * step, high), viewer="high")
        assert gpu.band_bakes == bakes and gpu._band_levels["high"] == gpu._band_levels[None] + 3
        # a window made twice as wide gets band images at its resolution (baked again); a smaller view after it
        # does not shrink them back (two views of different widths would re-bake every frame)
        narrow = at(base[0] + 0.1 * step, base[2])
        tile, bakes = gpu.band_layout.tile_w, gpu.band_bakes
        wide = replace(narrow, width=4 * narrow.width)
        gpu.ensure_band(cell, wide)
        assert gpu.band_layout.tile_w >= 3 * tile and gpu.band_bakes == bakes + 1
        gpu.ensure_band(cell, narrow)
        gpu.ensure_band(cell, wide)
        assert gpu.band_layout.tile_w >= 3 * tile and gpu.band_bakes == bakes + 1


def test_debug_view_colours_cells_by_level(tmp_path):
    grass = SMALL + "grid_x = 12\ngrid_z = 12\n"
    camera = _camera((0.0, 30.0, 560.0), pitch=-6.0)
    plain = np.asarray(render_app(_app(tmp_path, grass, camera), 120, 90), np.int16)
    debug = np.asarray(render_app(_app(tmp_path, grass + "debug_levels = true\n", camera, name="d.toml"), 120, 90),
                       np.int16)
    saturation = lambda img: (img.max(axis=2) - img.min(axis=2))  # noqa: E731
    assert (saturation(debug) > 90).mean() > 3 * max((saturation(plain) > 90).mean(), 1e-3)


@pytest.mark.parametrize("preset, height, cell", [("paper", 30.0, 100.0), ("lawn", 0.25, 1.0),
                                                   ("meadow", 2.2, 4.0)])
def test_presets_render(tmp_path, preset, height, cell):
    grass = f'preset = "grass_field/{preset}"\ngrid_x = 4\ngrid_z = 4\ncell_variants = 2\n'
    camera = _camera((0.0, height, 2.0 * cell), pitch=-12.0, far=50.0 * cell)
    image = np.asarray(render_app(_app(tmp_path, grass, camera, terrain=False), 96, 72), np.int16)
    sky = np.asarray(render_app(_app(tmp_path, "grid_x = 1\ngrid_z = 1\nplants_per_cell = 1\ncell_size = 0.001\n",
                                     camera, terrain=False, name="sky.toml"), 96, 72), np.int16)
    covered = np.abs(image - sky).max(axis=2) > 30
    assert covered.mean() > 0.05, f"{preset}: grass covers only {covered.mean():.1%} of the image"


def test_draws_without_multi_draw_indirect_match(tmp_path):
    """Before GL 4.3 (macOS stops at 4.1) each variant is one draw with rebound offsets instead of one command
    of a multi-draw indirect call: the same pixels, from more draw calls."""
    app = _app(tmp_path, SMALL + "grid_x = 6\ngrid_z = 6\n", _camera((0.0, 24.0, 40.0), pitch=-22.0))
    with rendered(app, 160, 120) as renderer:
        gpu = _gpu(app)
        assert gpu.multi_draw  # llvmpipe offers GL 4.5
        indirect, calls = np.asarray(renderer.read_image(), np.int16), gpu.draw_calls
        gpu.multi_draw = False
        app.render_frame()
        single = np.asarray(renderer.read_image(), np.int16)
        assert gpu.draw_calls > calls
        assert np.array_equal(single, indirect)


def test_rendering_leaves_the_state_alone(tmp_path):
    grass = SMALL + "grid_x = 8\ngrid_z = 8\n"
    camera = _camera((0.0, 30.0, 300.0))
    drawn, plain = _app(tmp_path, grass, camera), _app(tmp_path, grass, camera, name="b.toml")
    render_app(drawn, 64, 48, frames=3)
    plain.step(3)
    assert drawn.state_hash() == plain.state_hash()
    assert drawn.world.single(GrassFieldState).placed is not None


def test_blended_views_variant_renders_like_the_swap_rule(tmp_path):
    """blend_views compiles the impostor shader with BLEND_VIEWS (two atlas samples); the image stays close."""
    grass = SMALL + "grid_x = 12\ngrid_z = 12\n"
    camera = _camera((0.0, 30.0, 560.0), pitch=-6.0)
    plain = np.asarray(render_app(_app(tmp_path, grass, camera), 120, 90), np.int16)
    blended = np.asarray(render_app(_app(tmp_path, grass + "blend_views = true\n", camera, name="b.toml"), 120, 90),
                         np.int16)
    for debug in (False, True):  # the debug variant of the blending shader compiles too
        extra = "debug_levels = true\n" if debug else ""
        render_app(_app(tmp_path, grass + "blend_views = true\n" + extra, camera, name=f"d{debug}.toml"), 32, 24)
    assert 0.0 < np.abs(plain - blended).mean() < 6.0  # rectangles differ only where two views are mixed


def test_a_field_despawned_and_spawned_again_leaves_no_per_view_state_behind(tmp_path):
    """Each respawn is a new entity: the old one's impostor orientations and frame plans (per entity and view,
    sized by its cells) go with its GL resources instead of piling up."""
    app = _app(tmp_path, SMALL + "grid_x = 4\ngrid_z = 4\n", _camera((0.0, 24.0, 40.0), pitch=-22.0), terrain=False)
    renderer = make_renderer(app, 48, 36)
    try:
        for _ in range(3):
            entity = respawn(app, "grass")
            app.step(1)
            app.render_frame()
            feature = _feature(app)
            assert set(feature.orientations) == set(feature.plans) == {(entity, "view0")}
            assert list(feature.fields) == [entity]
    finally:
        renderer.release()
        app.renderer = None


def _walled(app: App, height: float) -> None:
    """The ground made flat but for a wall ``height`` high along z over x in [80, 160] (257 x 257 points, 10 m
    apart, centred on the origin)."""
    from engine.builtin import Terrain, find_named
    from engine.heightfield import HeightField

    terrain = app.world.get(find_named(app.world, "ground"), Terrain)
    h = np.zeros((257, 257))
    h[:, 136:145] = height
    terrain.field = HeightField(h, 10.0, terrain.field.origin)


@pytest.mark.parametrize("far", [False, True])
def test_the_terrains_shadow_falls_on_the_grass(tmp_path, far):
    """Behind a wall, under a low sun from +x, the plants (levels 0-3) and the cached images (level 4) lose the
    sun's light; beyond the shade's edge the picture keeps its bits."""
    grass = DENSE + "grid_x = 8\ngrid_z = 8\n"
    camera = (_camera((-60.0, 900.0, 700.0), pitch=-52.0) if far else
              _camera((-5.0, 45.0, -150.0), yaw=90.0, pitch=-25.0))
    images = {}
    for on, hide in ((True, False), (False, False), (False, True)):
        cam = camera + ('hide_features = ["grass_field"]\n' if hide else "")
        app = _app(tmp_path, grass, cam)
        app.config.render.sun_direction = (1.0, 0.5, 0.0)  # tan(elevation) 0.5: a 100 m wall shades 200 m
        app.config.render.terrain_shadows = on
        app.config.render.shadows = False
        app.config.render.fog_density = 0.0
        _walled(app, 100.0)
        with rendered(app, 160, 120) as renderer:
            images[on, hide] = np.asarray(renderer.read_image()).astype(float)
            view = renderer.views[0]
            if hide:
                continue
            gpu = _gpu(app)
            plan = _plan(app)
            assert len(plan.impostor_cells) > 10 if far else sum(len(p) for p in plan.plants) > 20
            sun = gpu.plant_records[:, 7]
            x = gpu.data.placed.plant_position[:, 0]
            if on:  # the shade reaches from the wall's foot (x = 70) to x = -120, softened over a cell or two
                assert (sun[(x > -100.0) & (x < 60.0)] == 0.0).all()
                assert (sun[(x < -135.0) | (x > 175.0)] == 1.0).all()
                assert (sun < 1.0).sum() > 0.15 * len(sun)
            else:
                assert (sun == 1.0).all()
    grass_pixels = np.abs(images[False, False] - images[False, True]).sum(axis=-1) > 20.0

    x = ground_of_pixels(view)[..., 0]  # where each pixel's ray meets the ground (y = 0)
    shaded = grass_pixels & (x > -90.0) & (x < 50.0)
    lit = grass_pixels & (x < -300.0)  # a pixel shows grass up to 20 m tall in front of where its ray lands
    assert shaded.sum() > 20 and lit.sum() > 20
    on, off = images[True, False], images[False, False]
    assert on[shaded].sum() < 0.8 * off[shaded].sum()
    np.testing.assert_allclose(on[lit], off[lit], atol=2.0)
    assert ((off - on).sum(axis=-1) < -3.0).sum() == 0  # nothing brighter


@pytest.mark.parametrize("case", ["near", "far", "band"])
def test_a_view_that_hides_the_terrain_gets_none_of_its_shadow_on_the_grass(tmp_path, case):
    """Camera hide_features = ["terrain"]: the plants, the level-4 images and the band are lit as without the
    terrain's shadow (the hidden wall shades nothing in that view)."""
    grass, camera = {
        "near": (DENSE + "grid_x = 8\ngrid_z = 8\n",
                 _camera((-5.0, 45.0, -150.0), yaw=90.0, pitch=-25.0)),
        "far": (DENSE + "grid_x = 8\ngrid_z = 8\n",
                _camera((-60.0, 900.0, 700.0), pitch=-52.0)),
        "band": (SMALL + "grid_x = 24\ngrid_z = 24\n", _camera((0.0, 40.0, 0.0), yaw=180.0, pitch=-3.0))}[case]
    images = {}
    for on in (True, False):
        app = _app(tmp_path, grass, camera + 'hide_features = ["terrain"]\n')
        app.config.render.sun_direction = (1.0, 0.5, 0.0)
        app.config.render.terrain_shadows = on
        app.config.render.shadows = False
        _walled(app, 100.0)
        with rendered(app, 160, 120) as renderer:
            images[on] = np.asarray(renderer.read_image()).astype(float)
            assert (renderer.terrain_shadow is not None) == on
            gpu = _gpu(app)
            plan = _plan(app)
            assert {"near": sum(len(p) for p in plan.plants) > 20, "far": len(plan.impostor_cells) > 10,
                    "band": plan.band_cell is not None and plan.band_sides.any()}[case]
            if on:
                assert (gpu.plant_records[:, 7] < 1.0).sum() > 0.05 * len(gpu.plant_records)
    np.testing.assert_array_equal(images[True], images[False])


def _use_sun(renderer, sun) -> None:
    renderer.use_settings(renderer.settings.model_copy(update={"sun_direction": sun}))


def test_a_new_sun_relights_the_cached_images_without_baking_them_again(tmp_path):
    """The LOD cache holds unlit images (albedo, normal): a new sun (or sky) re-bakes nothing, and the level-4
    picture is the one a field started under that sun draws."""
    grass, camera = SMALL + "grid_x = 16\ngrid_z = 16\nmax_level = 4\n", _camera((0.0, 40.0, 700.0), pitch=-5.0)
    app = _app(tmp_path, grass, camera)
    with rendered(app, 96, 72) as renderer:
        gpu = _gpu(app)
        assert gpu.baked_views == 36 and len(_plan(app).impostor_cells) > 50
        before = np.asarray(renderer.read_image()).astype(float)
        _use_sun(renderer, (-0.6, 0.3, 0.2))
        app.render_frame()
        assert gpu.baked_views == 36  # nothing baked again
        after = np.asarray(renderer.read_image()).astype(float)
    assert np.abs(after - before).max() > 10.0  # the images follow the new sun
    fresh = _app(tmp_path, grass, camera, name="fresh.toml")
    fresh.config.render.sun_direction = (-0.6, 0.3, 0.2)
    with rendered(fresh, 96, 72) as renderer:
        np.testing.assert_array_equal(np.asarray(renderer.read_image()).astype(float), after)


def _mean_grass_colour(tmp_path, sun, turns: bool, name: str) -> np.ndarray:
    """The mean colour of the level-4 grass pixels of a field seen from afar, its cells turned or not."""
    grass = SMALL + "grid_x = 16\ngrid_z = 16\nmax_level = 4\n"
    camera = _camera((0.0, 60.0, 1000.0), pitch=-6.0)
    images = []
    for hide in (False, True):
        app = _app(tmp_path, grass, camera + ('hide_features = ["grass_field"]\n' if hide else ""),
                   name=f"{name}{hide}.toml")
        app.config.render.sun_direction = sun
        app.config.render.fog_density = 0.0
        app.config.render.shadows = False
        if not turns:
            for _, (state,) in app.world.query(GrassFieldState):
                state.cell_turn[:] = 0
        with rendered(app, 160, 120) as renderer:
            images.append(np.asarray(renderer.read_image()).astype(float)[..., :3])
            if not hide:
                assert len(_plan(app).impostor_cells) > 150
    grass_pixels = np.abs(images[0] - images[1]).sum(axis=-1) > 6.0
    assert grass_pixels.sum() > 800
    return images[0][grass_pixels].mean(axis=0)


@pytest.mark.parametrize("sun", [(-0.2, 0.4, -0.9), (0.9, 0.15, -0.3)])
def test_a_cells_quarter_turn_does_not_turn_the_light_on_its_cached_image(tmp_path, sun):
    """Cells show their layout turned by quarter turns; the cached images of a layout are lit in the world's frame
    (the normals turned with the cell), so a field of turned cells is lit as one of unturned cells under a low sun.
    Baked lit in the layout's frame, 3 cells in 4 were lit from a sun turned with them (45 % brighter against the
    light)."""
    turned = _mean_grass_colour(tmp_path, sun, True, "turned")
    straight = _mean_grass_colour(tmp_path, sun, False, "straight")
    np.testing.assert_allclose(turned, straight, rtol=0.06)


def test_the_band_is_captured_again_only_when_the_light_strays_past_the_tolerance(tmp_path):
    """The band's images are captured lit: a sun moved by less than BAND_LIGHT_TOLERANCE keeps them (a sun moving
    every frame does not re-capture every frame), a larger move captures them again."""
    app = _app(tmp_path, SMALL + "grid_x = 24\ngrid_z = 24\n", _camera((0.0, 40.0, 0.0), yaw=180.0, pitch=-3.0))
    app.config.render.sun_direction = (1.0, 1.0, 0.0)
    with rendered(app, 96, 72) as renderer:
        gpu = _gpu(app)
        assert _plan(app).band_cell is not None and gpu.band_bakes >= 1
        bakes = gpu.band_bakes
        for degrees in (0.3, 0.6, 0.9):  # every step measured from the light the band holds
            a = np.radians(45.0 + degrees)
            _use_sun(renderer, (float(np.cos(a)), float(np.sin(a)), 0.0))
            app.render_frame()
            assert gpu.band_bakes == bakes
        a = np.radians(46.5)
        _use_sun(renderer, (float(np.cos(a)), float(np.sin(a)), 0.0))
        app.render_frame()
        assert gpu.band_bakes == bakes + 1
        renderer.use_settings(renderer.settings.model_copy(update={"sky_top": (0.3, 0.45, 0.85)}))  # +20 % red
        app.render_frame()
        assert gpu.band_bakes == bakes + 2


def test_the_plants_receive_the_suns_shadow_map(tmp_path):
    """A slab floating over the field shades the ground and the blades standing in its shadow (levels 0-3 take
    the shadow map per vertex); the plants no caster can reach keep the plain shader."""
    roof = """
[[entities]]
name = "roof"
[entities.components.Transform]
position = [-50.0, 30.0, -150.0]
scale = [20.0, 2.0, 30.0]
[entities.components.Mesh]
shape = "box"
color = [0.8, 0.3, 0.2]
"""
    grass = DENSE + "grid_x = 8\ngrid_z = 8\n"
    images, shadowed = {}, {}
    for shadows, hide in ((True, False), (False, False), (True, True)):
        camera = _camera((-5.0, 45.0, -150.0), yaw=90.0, pitch=-25.0)
        camera += 'hide_features = ["grass_field"]\n' if hide else ""
        app = _app(tmp_path, grass, camera + roof)
        app.config.render.sun_direction = (0.2, 0.7, 1.0)  # the slab's shadow falls towards -z, in view
        app.config.render.shadows = shadows
        app.config.render.shadow_distance = 300.0
        app.config.render.fog_density = 0.0
        with rendered(app, 160, 120) as renderer:
            images[shadows, hide] = np.asarray(renderer.read_image()).astype(float)
            if not hide:
                gpu = _gpu(app)
                shadowed[shadows] = gpu.shadowed_plants
                assert sum(len(p) for p in _plan(app).plants) > 20
    assert shadowed[False] == 0 and shadowed[True] > 0
    grass = np.abs(images[True, False] - images[True, True]).sum(axis=-1) > 20.0  # blades drawn over the ground
    darker = (images[False, False] - images[True, False]).sum(axis=-1) > 40.0
    assert (grass & darker).sum() > 40  # blades in the slab's shadow lost the sun


def test_the_cached_images_receive_the_suns_shadow_map(tmp_path):
    """Level 4: a slab 100 m over a flat field, seen from far enough that every cell is a cached image, shades the
    images' grass where the slab's shadow falls on the ground (the shadow map looked up per pixel at the depth the
    atlas holds); the grass away from it keeps its bits; the rectangles no caster can reach keep the plain shader.
    Before, level 4 took no shadow from the map at all."""
    slab_centre, slab_half, height = np.array([0.0, 100.0, 0.0]), np.array([150.0, 2.0, 120.0]), 100.0
    slab = f"""
[[entities]]
name = "slab"
[entities.components.Transform]
position = {slab_centre.tolist()}
scale = {(2.0 * slab_half).tolist()}
[entities.components.Mesh]
shape = "box"
color = [0.8, 0.3, 0.2]
"""
    sun = np.array([0.3, 0.6, -0.8])  # the shadow falls towards the camera, in view
    grass = DENSE + "grid_x = 8\ngrid_z = 8\n"
    images, counts = {}, {}
    for shadows, hide in ((True, False), (False, False), (True, True)):
        camera = _camera((-60.0, 900.0, 700.0), pitch=-52.0) + ('hide_features = ["grass_field"]\n' if hide else "")
        app = _app(tmp_path, grass, camera + slab)
        app.config.render.sun_direction = tuple(sun)
        app.config.render.shadows = shadows
        app.config.render.shadow_distance = 2500.0
        app.config.render.fog_density = 0.0
        _walled(app, 0.0)
        with rendered(app, 320, 240) as renderer:
            images[shadows, hide] = np.asarray(renderer.read_image()).astype(float)
            view = renderer.views[0]
            if not hide:
                plan = _plan(app)
                gpu = _gpu(app)
                assert len(plan.impostor_cells) > 20 and sum(len(p) for p in plan.plants) == 0
                counts[shadows] = gpu.shadowed_rectangles
    assert counts[False] == 0 and 0 < counts[True] < 64  # receiver culling: not every cell
    grass = np.abs(images[True, False] - images[True, True]).sum(axis=-1) > 20.0
    ground = ground_of_pixels(view)
    # the slab's shadow on the ground: its footprint moved away from the sun by height / tan(elevation)
    shift = -sun[[0, 2]] / np.linalg.norm(sun) * (height / (sun[1] / np.linalg.norm(sun)))
    rel = np.abs(ground[..., [0, 2]] - (slab_centre[[0, 2]] + shift))
    inside = grass & (rel < slab_half[[0, 2]] - 25.0).all(axis=-1)  # grass stands up to 20 m over its ground
    outside = grass & (rel > slab_half[[0, 2]] + 60.0).any(axis=-1)
    assert inside.sum() > 40 and outside.sum() > 100
    on, off = images[True, False], images[False, False]
    assert (on[inside].sum(axis=-1) < off[inside].sum(axis=-1) - 20.0).mean() > 0.9  # the sun's share is gone
    np.testing.assert_allclose(on[outside], off[outside], atol=2.0)


def test_what_stands_in_the_cached_images_grass_is_hidden_only_by_the_grass_in_front(tmp_path):
    """A tower 60 m tall stands in a field drawn as cached images (level 4), seen from high above: no grass (20 m
    tall) lies between the eye and the tower's top, so its top keeps the bits it has without the grass.  The
    rectangles write the depth of their texels' grass; drawn at the rectangle's depth (the paper's way, pushed in
    front of the whole cell, `grass_depth` off) the grass behind the tower was painted over its top."""
    tower = """
[[entities]]
name = "tower"
[entities.components.Transform]
position = [30.0, 30.0, 20.0]
scale = [40.0, 60.0, 40.0]
[entities.components.Mesh]
shape = "box"
color = [0.9, 0.1, 0.1]
"""
    grass = DENSE + "grid_x = 8\ngrid_z = 8\n"
    images = {}
    for case in ("no grass", "grass", "rectangle depth"):
        camera = _camera((-60.0, 700.0, 600.0), pitch=-45.0)
        camera += 'hide_features = ["grass_field"]\n' if case == "no grass" else ""
        app = _app(tmp_path, grass, camera + tower)
        app.config.render.fog_density = 0.0
        app.config.render.shadows = False
        _walled(app, 0.0)
        with rendered(app, 320, 240) as renderer:
            if case == "rectangle depth":
                _gpu(app).grass_depth = False
                app.render_frame()
            images[case] = np.asarray(renderer.read_image()).astype(float)
            view = renderer.views[0]
            if case != "no grass":
                plan = _plan(app)
                assert len(plan.impostor_cells) > 20 and sum(len(p) for p in plan.plants) == 0
    s = np.linspace(-17.0, 17.0, 60)
    top = {world_pixel(view, (30.0 + x, 60.0, 20.0 + z)) for x in s for z in s}  # the top, inset by 3 m
    rows, cols = np.array(sorted(top)).T
    assert len(top) > 100
    clean, drawn, old = (images[k][rows, cols] for k in ("no grass", "grass", "rectangle depth"))
    assert (np.abs(old - clean).max(axis=-1) > 10.0).sum() > 5  # the old way covers part of the top
    np.testing.assert_allclose(drawn, clean, atol=2.0)
    # and the grass is still drawn around the tower
    assert (np.abs(images["grass"] - images["no grass"]).max(axis=-1) > 10.0).sum() > 2000


def test_the_depth_images_mip_levels_cover_what_the_colours_alpha_test_passes(tmp_path):
    """The atlas's depth image (depth · coverage, coverage) is box-filtered over the same texels as the colour's
    coverage-preserving levels, so wherever a level's alpha test passes its depth has coverage and holds the mean
    depth of the covered texels below it.  GL's generated levels sampled other texels at odd sizes (819 → 409 →
    204): texels with grass in colour and none in depth, read as depth 0, the bake camera's near plane (2 · depth
    in front of the cell)."""
    grass = DENSE + "grid_x = 4\ngrid_z = 4\n"
    app = _app(tmp_path, grass, _camera((0.0, 30.0, 0.0)), terrain=False)
    with rendered(app, 32, 24) as renderer:
        gpu = _gpu(app)
        gpu.ensure_impostors()
        w, h = gpu.layout.size
        assert w % 2 or (w // 2) % 2 or h % 2 or (h // 2) % 2  # the layout this test is about: an odd level
        base = np.frombuffer(gpu.atlas_depth.read(), np.float16).reshape(h, w, 2).astype(np.float64)
        for level in range(1, ATLAS_MIP_LEVELS + 1):
            lw, lh, k = w >> level, h >> level, 2 ** level
            colour = np.frombuffer(gpu.atlas.read(level=level), np.uint8).reshape(lh, lw, 4)
            depth = np.frombuffer(gpu.atlas_depth.read(level=level), np.float16).reshape(lh, lw, 2).astype(float)
            passes = colour[..., 3] >= 128
            assert passes.sum() > 100
            assert not (passes & (depth[..., 1] <= 0.0)).any(), level
            box = base[:lh * k, :lw * k].reshape(lh, k, lw, k, 2).mean(axis=(1, 3))
            np.testing.assert_allclose(depth[passes], box[passes], atol=2e-3, rtol=2e-3)


@pytest.mark.parametrize("blend", [False, True])
def test_the_rectangles_grass_depth_lies_behind_the_rectangle(tmp_path, monkeypatch, blend):
    """Each level-4 fragment's depth (GRASS_DEPTH) is that of its texel's grass, at most the depth margin in front
    of the rectangle (which lies in front of the whole cell).  With ``blend_views`` the depth was read from the
    first view's image alone: where only the second view has grass it read depth 0, the bake camera's near plane,
    and wrote a point twice the cell's depth in front of it (up to 95 m in front of the rectangle)."""
    from systems.grass_field.render import FieldGpu

    grass = DENSE + "grid_x = 8\ngrid_z = 8\n"
    grass += "blend_views = true\n" if blend else ""
    captured, original = {}, FieldGpu.draw

    def draw(self, fbo, plan, view, *args, **kwargs):  # the view's depth right after the grass's pass
        original(self, fbo, plan, view, *args, **kwargs)
        w, h = fbo.size
        captured["depth"] = np.frombuffer(fbo.read(components=1, attachment=-1, dtype="f4"), np.float32).reshape(h, w)
        captured["proj"], captured["margin"] = view.proj.astype(np.float64), self._depth_uniforms(True)["depth_margin"]

    monkeypatch.setattr(FieldGpu, "draw", draw)
    distance = {}
    for grass_depth in (True, False):
        app = _app(tmp_path, grass, _camera((-60.0, 500.0, 900.0), pitch=-25.0, far=3000.0))
        app.config.render.fog_density = 0.0
        app.config.render.shadows = False
        _walled(app, 0.0)
        with rendered(app, 320, 240) as renderer:
            gpu = _gpu(app)
            gpu.grass_depth = grass_depth
            app.render_frame()
            plan = _plan(app)
            assert len(plan.impostor_cells) > 20 and sum(len(p) for p in plan.plants) == 0
            if blend:
                assert (plan.impostor_blend > 0.5).sum() > 5
        p = captured["proj"]
        distance[grass_depth] = p[2, 3] / (2.0 * captured["depth"].astype(np.float64) - 1.0 + p[2, 2])  # eye -z
    grass_pixels = distance[False] < distance[True] - 1.0
    assert grass_pixels.sum() > 2000
    nearer = distance[False] - distance[True]  # how far the grass's depth lies in front of the rectangle's
    assert nearer.max() <= captured["margin"] + 1.0, (int((nearer > captured["margin"] + 1.0).sum()), nearer.max())
