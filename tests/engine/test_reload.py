"""Hot reload: live parameters, kept state, structural rebuilds of one component, invalid edits kept out."""

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from engine.app import App
from engine.config import ConfigModel
from engine.registry import default_registry
from engine.reload import HotReloader, ReloadStatus
from engine.schedule import Stage
from engine.script import Scripts


class PumpConfig(ConfigModel):
    rate: float = Field(1.0, ge=0.0, le=100.0)
    capacity: int = Field(4, ge=1, le=1000)


@dataclass
class PumpState:
    levels: np.ndarray


def pump_system(world, dt):
    for _, (cfg, state) in world.query(PumpConfig, PumpState):
        state.levels += cfg.rate


def registry():
    reg = default_registry([])
    reg.add_component("Pump", PumpConfig, lambda cfg, ctx: [cfg, PumpState(np.zeros(cfg.capacity))],
                      structural=("capacity",))
    reg.add_system(pump_system, Stage.SIMULATION, name="pump")
    return reg


SCENE = """
[[entities]]
name = "pump"
scripts = [{{ name = "spin", params = {{ speed = {speed} }} }}]
[entities.components.Transform]
[entities.components.Pump]
preset = "pump/basic"
capacity = {capacity}
[[entities]]
name = "other"
[entities.components.Pump]
rate = 5.0
"""


def setup(tmp_path, rate="2.0", capacity=4, speed=10.0):
    root = tmp_path / "configs"
    (root / "scenes").mkdir(parents=True)
    (root / "effects" / "pump").mkdir(parents=True)
    (root / "effects" / "pump" / "basic.toml").write_text(f"rate = {rate}\n")
    scene = root / "scenes" / "s.toml"
    scene.write_text(SCENE.format(capacity=capacity, speed=speed))
    reg = registry()
    reg.components["Pump"].preset_dir = "pump"
    app = App(scene, registry=reg, strict=True)
    return app, HotReloader(app), root


def state_of(app, index=0):
    return app.world.get(app.records[index].entity, PumpState)


def test_changed_parameter_is_live_next_tick_and_state_kept(tmp_path):
    app, reloader, root = setup(tmp_path)
    app.step(3)
    state = state_of(app)
    assert state.levels[0] == 6.0
    (root / "effects" / "pump" / "basic.toml").write_text("rate = 10.0\n")  # edit the preset file
    assert reloader.poll()
    app.step(1)
    assert state_of(app) is state and state.levels[0] == 16.0  # kept state, new rate within one tick
    assert not reloader.poll()  # nothing changed since


def test_structural_change_rebuilds_only_that_component(tmp_path):
    app, reloader, root = setup(tmp_path)
    app.step(2)
    other = state_of(app, 1)
    scene = root / "scenes" / "s.toml"
    scene.write_text(SCENE.format(capacity=8, speed=10.0))
    assert reloader.poll()
    assert state_of(app).levels.shape == (8,) and state_of(app).levels.sum() == 0.0  # rebuilt
    assert state_of(app, 1) is other and other.levels[0] == 10.0  # the other entity untouched
    assert any("rebuilt" in c for c in reloader.status.last_changes)


def test_invalid_edit_keeps_last_good_config_and_reports(tmp_path):
    app, reloader, root = setup(tmp_path)
    preset = root / "effects" / "pump" / "basic.toml"
    preset.write_text("rat = 10.0\n")
    assert reloader.poll()
    status = app.world.resource(ReloadStatus)
    assert status.errors and "basic.toml" in status.errors[0] and "did you mean 'rate'" in status.errors[0]
    app.step(1)
    assert state_of(app).levels[0] == 2.0  # still the old rate
    preset.write_text("rate = 3.0\n")  # fixed: errors clear, new value live
    assert reloader.poll()
    app.step(1)
    assert status.errors == [] and state_of(app).levels[0] == 5.0


def test_script_parameters_reload_in_place(tmp_path):
    app, reloader, root = setup(tmp_path)
    app.step(1)
    script = app.world.get(app.records[0].entity, Scripts).slots[0].script
    (root / "scenes" / "s.toml").write_text(SCENE.format(capacity=4, speed=99.0))
    reloader.poll()
    assert app.world.get(app.records[0].entity, Scripts).slots[0].script is script
    assert script.params.speed == 99.0


def test_a_rebuild_that_fails_keeps_the_old_component(tmp_path):
    app, reloader, root = setup(tmp_path)
    spec = app.registry.components["Pump"]
    original = spec.build

    def failing(cfg, ctx):
        if cfg.capacity == 9:
            raise ValueError("capacity 9 needs a bigger tank")
        return original(cfg, ctx)

    spec.build = failing
    app.step(1)
    state = state_of(app)
    (root / "scenes" / "s.toml").write_text(SCENE.format(capacity=9, speed=10.0))
    reloader.poll()  # does not raise
    assert state_of(app) is state and any("bigger tank" in e for e in reloader.status.errors)


# ------------------------------------------------------------------ failures part-way, insertions, restarts
from pydantic import field_validator  # noqa: E402

from engine.app import TimeControl  # noqa: E402
from engine.config import ConfigError  # noqa: E402
from engine.script import Script, script  # noqa: E402


class BoomParams(ConfigModel):
    fuse: float = 1.0

    @field_validator("fuse")
    @classmethod
    def _fuse(cls, v: float) -> float:
        return 1.0 / v  # ZeroDivisionError for 0: not a ValueError


@script("boom")
class Boom(Script):
    Params = BoomParams

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        if self.params.fuse < 0.0:
            raise RuntimeError("the script's constructor failed")


@script("dud")
class Dud(Script):
    def __init__(self, *args, **kwargs) -> None:
        raise RuntimeError("a script that cannot start")


PLAIN = """
[[entities]]
name = "{first}"
[entities.components.Pump]
rate = 1.0
[[entities]]
name = "second"
scripts = [{{ name = "{script}", params = {{ fuse = {fuse} }} }}]
[entities.components.Pump]
rate = 2.0
"""


def plain(first="first", fuse=1.0, script="boom"):
    return PLAIN.format(first=first, fuse=fuse, script=script)


def plain_app(tmp_path, first="first", fuse=1.0):
    scene = tmp_path / "s.toml"
    scene.write_text(plain(first, fuse))
    reg = registry()
    reg.add_scripts([Boom, Dud])
    return App(scene, registry=reg), scene


def test_a_script_whose_constructor_or_validator_raises_is_a_config_error_naming_the_key(tmp_path):
    for fuse, needle in ((-1.0, "RuntimeError: the script's constructor failed"), (0.0, "ZeroDivisionError")):
        try:
            plain_app(tmp_path, fuse=fuse)
        except ConfigError as exc:
            text = str(exc)
            assert "s.toml" in text and "entities[1].scripts[0]" in text and needle in text
        else:
            raise AssertionError("loading should have failed")


def test_a_reload_that_fails_part_way_keeps_the_records_true_and_the_next_reload_spawns_nothing_twice(tmp_path):
    app, scene = plain_app(tmp_path)
    reloader = HotReloader(app)
    scene.write_text(plain("renamed", script="dud").replace("fuse = 1.0", ""))  # a new entity; a script that fails
    reloader.reload()
    assert any("entities[1] 'second'" in e and "a script that cannot start" in e for e in reloader.status.errors)
    scene.write_text(plain("renamed"))
    reloader.reload()
    alive = [e for e in app.world.entities if app.world.try_get(e, PumpConfig) is not None]
    assert sorted(r.entity for r in app.records) == sorted(alive) and len(alive) == 2
    assert [r.name for r in app.records] == ["renamed", "second"]


def test_an_entity_inserted_above_the_others_keeps_their_simulation_state(tmp_path):
    app, scene = plain_app(tmp_path)
    app.step(3)
    states = [state_of(app, 0), state_of(app, 1)]
    scene.write_text('[[entities]]\nname = "marker"\n' + plain())
    HotReloader(app).reload()
    assert [r.name for r in app.records] == ["marker", "first", "second"]
    assert state_of(app, 1) is states[0] and state_of(app, 2) is states[1] and states[1].levels[0] == 6.0


def test_a_restart_that_cannot_build_the_scene_keeps_the_running_world(tmp_path):
    app, scene = plain_app(tmp_path)
    app.step(2)
    world, state = app.world, state_of(app, 1)
    app.plan.entities[1].scripts[0] = (Boom, BoomParams.model_construct(fuse=-1.0), True)  # as a broken asset would
    app.world.resource(TimeControl).restart_requested = True
    app.step(1)
    assert app.world is world and state_of(app, 1) is state and state.levels[0] == 6.0
    assert app.restart_errors and "entities[1].scripts[0]" in app.restart_errors[0]
    assert not world.resource(TimeControl).restart_requested  # asked once, not every tick


# --------------------------------------------------- scene settings, files a failed edit names, empty saves
import shutil  # noqa: E402

from engine.config import STOCK_CONFIGS, CrossFieldError  # noqa: E402
from pydantic import ValidationInfo, model_validator  # noqa: E402


class SpringConfig(ConfigModel):
    """An explicit integrator with a step limit, as the water surface has: stiffness · fixed_dt² < 1."""

    stiffness: float = Field(100.0, gt=0.0, le=1e7)

    @model_validator(mode="after")
    def _stable(self, info: ValidationInfo):
        dt = (info.context or {}).get("fixed_dt")
        if dt is not None:
            check_spring(self.stiffness, dt)
        return self


def check_spring(stiffness: float, dt: float) -> None:
    if stiffness * dt * dt >= 1.0:
        raise CrossFieldError("stiffness", f"stiffness {stiffness:g} is unstable at fixed_dt {dt:g} s")


def spring_system(world, dt):  # raises, as a simulation's stability check does (systems/water_surface/simulate.py)
    for _, (cfg,) in world.query(SpringConfig):
        check_spring(cfg.stiffness, dt)


def spring_registry():
    reg = registry()
    reg.add_component("Spring", SpringConfig, structural=())
    reg.add_system(spring_system, Stage.SIMULATION, name="spring")
    return reg


SPRING = """
[scene]
{settings}
[[entities]]
name = "spring"
[entities.components.Spring]
stiffness = {stiffness}
"""


def spring_app(tmp_path, settings="", stiffness=100.0, **kwargs):
    scene = tmp_path / "s.toml"
    scene.write_text(SPRING.format(settings=settings, stiffness=stiffness))
    app = App(scene, registry=spring_registry(), **kwargs)
    return app, HotReloader(app), scene


def test_fixed_dt_and_max_catchup_steps_apply_live_and_the_step_is_the_one_validated(tmp_path):
    app, reloader, scene = spring_app(tmp_path)
    app.step(2)
    # stable at 1/1000 s only: the reload validated it there, so the clock must run at 1/1000 s
    scene.write_text(SPRING.format(settings="fixed_dt = 0.001\nmax_catchup_steps = 12", stiffness=10000.0))
    assert reloader.poll() and reloader.status.errors == []
    assert app.dt == 0.001 and app.clock.max_steps == 12 and app.config.scene.fixed_dt == 0.001
    assert any("fixed_dt" in c and "0.001" in c for c in reloader.status.last_changes)
    app.step(3)  # the old code kept 1/60 s and the spring system raised here, every tick
    assert app.advance(0.0105) == 10


def test_a_fixed_dt_an_entity_spawned_while_running_cannot_run_at_is_refused(tmp_path):
    from engine.builtin import Name

    app, reloader, scene = spring_app(tmp_path)
    extra = app.world.spawn()  # as a prefab or a spawner script would: validated at the step it was spawned at
    app.world.add(extra, Name("late"))
    app.world.add(extra, SpringConfig.model_validate({"stiffness": 1000.0}, context={"fixed_dt": app.dt}))
    app.step(1)
    scene.write_text(SPRING.format(settings="fixed_dt = 0.05", stiffness=100.0))  # fine for the scene's spring
    assert reloader.poll()
    errors = reloader.status.errors
    assert len(errors) == 1 and "s.toml" in errors[0] and "scene.fixed_dt" in errors[0] and "'late'" in errors[0]
    assert "unstable at fixed_dt 0.05" in errors[0]
    assert app.dt == 1.0 / 60.0 and app.plan.config.scene.fixed_dt == 1.0 / 60.0
    app.step(2)  # the running world keeps the step it can run at


def test_a_seed_edit_applies_on_restart_and_says_so(tmp_path):
    app, reloader, scene = spring_app(tmp_path, settings="seed = 1")
    world = app.world
    scene.write_text(SPRING.format(settings="seed = 2", stiffness=100.0))
    assert reloader.poll() and reloader.status.errors == []
    assert app.world is world and world.seed == 1  # a running world keeps its random streams
    assert any("seed 1 -> 2, applies on restart (R)" in c for c in reloader.status.last_changes)
    assert any("scene.seed" in w and "restart (R)" in w for w in reloader.status.warnings)
    app.restart()
    assert app.world.seed == 2
    assert not reloader.poll()  # the status moves to the new world and the settled note goes
    assert app.world.resource(ReloadStatus) is reloader.status
    assert not any("scene.seed" in w for w in reloader.status.warnings)


def test_a_seed_given_when_the_game_started_stays_and_the_edit_is_noted(tmp_path):
    app, reloader, scene = spring_app(tmp_path, settings="seed = 1", seed=7)
    scene.write_text(SPRING.format(settings="seed = 2", stiffness=100.0))
    assert reloader.poll() and reloader.status.errors == []
    assert any("scene.seed" in w and "seed 7 was given" in w for w in reloader.status.warnings)
    app.restart()
    assert app.world.seed == 7


def test_render_settings_reach_the_renderer_and_the_window_size_is_noted(tmp_path):
    app, reloader, scene = spring_app(tmp_path)
    settings = app.config.render
    from tests.render_utils import make_renderer

    make_renderer(app, 32, 20)  # sets app.renderer
    text = SPRING.format(settings="", stiffness=100.0)
    scene.write_text(text + '[render]\nexposure = 2.5\nsun_direction = [0.0, 2.0, 0.0]\nambient = 0.5\n'
                            'width = 1280\nvsync = false\n')
    assert reloader.poll() and reloader.status.errors == []
    renderer = app.renderer
    assert renderer.settings is app.config.render and renderer.settings.exposure == 2.5
    np.testing.assert_allclose(renderer.sun_direction, [0.0, 1.0, 0.0])
    assert renderer.ambient == 0.5
    assert app.config.render.width == settings.width and app.config.render.vsync == settings.vsync  # the window's
    assert any("render.width" in w and "not reloaded" in w for w in reloader.status.warnings)
    assert any("render.vsync" in w for w in reloader.status.warnings)
    renderer.release()
    app.renderer = None


def test_a_changed_plugin_list_is_reported_at_scene_plugins_and_the_world_kept(tmp_path):
    scene = tmp_path / "s.toml"
    body = '[[entities]]\nname = "a"\n[entities.components.Transform]\n'
    scene.write_text('[scene]\nplugins = ["render"]\n' + body)
    app = App(scene)
    reloader = HotReloader(app)
    app.step(1)
    entities = list(app.world.entities)
    scene.write_text('[scene]\nplugins = ["render", "energy_wave"]\n' + body
                     + "[entities.components.EnergyWaveEmitter]\n")
    assert reloader.poll()
    errors = reloader.status.errors
    assert len(errors) == 1 and "s.toml:2: scene.plugins" in errors[0] and "run it again" in errors[0]
    assert "[render] to [render, energy_wave]" in errors[0]
    assert not any("unknown component" in e or "not installed" in e for e in errors)
    assert list(app.world.entities) == entities and app.plan.config.scene.plugins == ["render"]
    scene.write_text('[scene]\nplugins = ["render"]\n' + body.replace('"a"', '"b"'))  # back: reloads
    assert reloader.poll() and reloader.status.errors == [] and app.records[0].name == "b"


def test_creating_the_missing_preset_a_failed_edit_names_reloads(tmp_path):
    app, reloader, root = setup(tmp_path)
    scene = root / "scenes" / "s.toml"
    scene.write_text(SCENE.format(capacity=4, speed=10.0).replace("pump/basic", "pump/mine"))
    assert reloader.poll() and "preset not found" in reloader.status.errors[0]
    assert not reloader.poll()  # the same broken content is not reported every poll
    (root / "effects" / "pump" / "mine.toml").write_text("rate = 7.0\n")
    assert reloader.poll() and reloader.status.errors == []
    app.step(1)
    assert state_of(app).levels[0] == 7.0


def test_fixing_the_broken_new_preset_a_failed_edit_names_reloads(tmp_path):
    app, reloader, root = setup(tmp_path)
    preset = root / "effects" / "pump" / "mine.toml"
    preset.write_text("rate = = 1\n")
    (root / "scenes" / "s.toml").write_text(SCENE.format(capacity=4, speed=10.0).replace("pump/basic", "pump/mine"))
    assert reloader.poll() and "mine.toml" in reloader.status.errors[0] and "syntax" in reloader.status.errors[0]
    preset.write_text("rate = 3.0\n")
    assert reloader.poll() and reloader.status.errors == []
    app.step(1)
    assert state_of(app).levels[0] == 3.0


def test_creating_the_missing_asset_a_failed_edit_names_reloads(tmp_path):
    app, reloader, root = setup(tmp_path)
    scene = root / "scenes" / "s.toml"
    terrain = '\n[[entities]]\nname = "ground"\n[entities.components.Terrain]\nsize_exponent = 3\n'
    scene.write_text(SCENE.format(capacity=4, speed=10.0) + terrain + 'texture = "assets/mine.png"\n')
    assert reloader.poll() and "texture not found" in reloader.status.errors[0]
    (root / "assets").mkdir()
    shutil.copy(STOCK_CONFIGS / "assets" / "sand.png", root / "assets" / "mine.png")
    assert reloader.poll() and reloader.status.errors == []
    assert [r.name for r in app.records] == ["pump", "other", "ground"]


def test_a_scene_file_emptied_by_a_save_in_progress_keeps_the_running_world(tmp_path):
    app, reloader, root = setup(tmp_path)
    scene = root / "scenes" / "s.toml"
    app.step(2)
    state, text = state_of(app), scene.read_text()
    scene.write_text("")  # an editor truncates, then writes
    assert reloader.poll()
    assert "s.toml" in reloader.status.errors[0] and "empty" in reloader.status.errors[0]
    assert not reloader.reload()  # F5 on the empty file: still held back
    assert len(app.records) == 2 and state_of(app) is state
    scene.write_text(text)  # the save completes: nothing was despawned, the simulation state is kept
    assert reloader.poll() and reloader.status.errors == []
    assert state_of(app) is state and state.levels[0] == 4.0
    scene.write_text("# nothing here\n")  # a scene meant to be empty says so
    assert reloader.poll() and reloader.status.errors == [] and app.records == []


def test_editing_a_height_map_a_running_terrain_reads_rebuilds_that_terrain(tmp_path):
    """The config names the same file, so nothing in the TOML changed: the file's own edit rebuilds the component
    that reads it (and a broken save keeps the running terrain until it is fixed)."""
    from PIL import Image

    from engine.builtin import Terrain

    app, reloader, root = setup(tmp_path)
    (root / "assets").mkdir()
    heightmap = root / "assets" / "hills.png"
    Image.fromarray(np.full((17, 17), 40, np.uint8), "L").save(heightmap)
    scene = root / "scenes" / "s.toml"
    scene.write_text(SCENE.format(capacity=4, speed=10.0) + '\n[[entities]]\nname = "ground"\n'
                     '[entities.components.Terrain]\nheightmap = "assets/hills.png"\n')
    assert reloader.poll() and reloader.status.errors == []
    ground = app.records[2].entity
    before = app.world.get(ground, Terrain).field.heights.copy()
    pump_levels = state_of(app).levels.copy()

    Image.fromarray(np.tile(np.arange(17, dtype=np.uint8) * 15, (17, 1)), "L").save(heightmap)
    assert reloader.poll() and reloader.status.errors == []
    assert "ground.Terrain: rebuilt (a file it reads changed)" in reloader.status.last_changes
    after = app.world.get(ground, Terrain).field.heights
    assert after.shape == before.shape and not np.array_equal(after, before)
    assert np.array_equal(state_of(app).levels, pump_levels)  # nothing else was touched

    heightmap.write_bytes(b"\x89PNG not really")  # a broken save: refused, the terrain stays
    assert reloader.poll() and "hills.png" in " ".join(reloader.status.errors)
    assert np.array_equal(app.world.get(ground, Terrain).field.heights, after)
    Image.fromarray(np.full((17, 17), 200, np.uint8), "L").save(heightmap)
    assert reloader.poll() and reloader.status.errors == []
    assert np.allclose(app.world.get(ground, Terrain).field.heights, 200 / 255 * 10.0)  # height_scale 10 m
    assert not reloader.poll()  # nothing more changed
