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
