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
