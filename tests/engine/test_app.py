from engine.app import App, TimeControl
from engine.script import Scripts
from engine.spatial import Transform

SCENE = "configs/scenes/sandbox.toml"


def spinner_rotation(app):
    for e, (scripts, t) in app.world.query(Scripts, Transform):
        if scripts.slots[0].name == "spin":
            return t.rotation.copy()


def test_pause_skips_simulation_and_the_stock_scripts_wait():
    calls = []
    app = App(SCENE)
    app.registry.schedule  # the sandbox has no simulation system of its own: add one
    app.schedule.add(lambda w, dt: calls.append(w.tick), "simulation", name="test.counter")
    try:
        app.step(2)
        app.world.resource(TimeControl).paused = True
        before = spinner_rotation(app)
        app.step(3)
        assert calls == [0, 1]  # simulation stage skipped while paused
        # scripts still run (menus, the pause key: the demo's Esc unpauses), but the stock spin script advances
        # game time, so it waits while ScriptContext.paused is set
        assert (spinner_rotation(app) == before).all()
        app.world.resource(TimeControl).paused = False
        app.step(1)
        assert calls == [0, 1, 5]
        assert (spinner_rotation(app) != before).any()
    finally:
        app.schedule.systems[:] = [s for s in app.schedule.systems if s.name != "test.counter"]
        app.schedule._sorted = None


def test_engine_pause_pauses_and_the_pause_key_toggles():
    """engine.pause pauses, so a rules script calling it twice (say, on two ways of losing in one tick) stays
    paused (was: it toggled without paused=, and the second call resumed the game); paused=False resumes;
    engine.toggle_pause is the pause key's toggle."""
    import pytest

    from engine.script import ScriptContext

    app = App(SCENE)
    ctx = ScriptContext(app.world, app.world.spawn(), "test")
    control = app.world.resource(TimeControl)
    assert ctx.call("engine.pause") is True and ctx.call("engine.pause") is True and control.paused
    assert ctx.call("engine.pause", paused=False) is False and not control.paused
    assert ctx.call("engine.toggle_pause") is True and control.paused
    assert ctx.call("engine.toggle_pause") is False and not control.paused
    with pytest.raises(TypeError, match="to toggle, call 'engine.toggle_pause'"):
        ctx.call("engine.pause", paused=None)
    assert not control.paused


def test_restart_rebuilds_the_scene_with_the_same_seed():
    app = App(SCENE, seed=4)
    fresh = App(SCENE, seed=4)
    fresh.step(10)
    app.step(30)
    app.world.resource(TimeControl).restart_requested = True
    app.step(1)  # restart happens at the end of this tick
    assert app.world.tick == 0
    app.step(10)
    assert app.state_hash() == fresh.state_hash()


def test_a_tick_runs_the_stages_in_order_and_applies_each_systems_commands_before_the_next(tmp_path):
    """Input, then scripts, then simulation, then post-simulation, every tick; a system's deferred commands are
    applied before the next system of the same stage runs, so that system sees the spawned entity."""
    from dataclasses import dataclass

    from engine.registry import default_registry
    from engine.schedule import Stage

    @dataclass
    class Marker:
        tick: int

    order, seen = [], []
    reg = default_registry()
    for stage in (Stage.POST_SIMULATION, Stage.SIMULATION, Stage.SCRIPT, Stage.INPUT):  # registered backwards
        reg.add_system(lambda world, dt, s=stage: order.append(s), stage, name=f"test.order.{stage.value}")

    def spawner(world, dt):
        world.commands.spawn(Marker(world.tick))

    def reader(world, dt):
        seen.append(sorted(m.tick for _, (m,) in world.query(Marker)))

    reg.add_system(spawner, Stage.SIMULATION, name="test.spawner")
    reg.add_system(reader, Stage.SIMULATION, name="test.reader", after=("test.spawner",))
    scene = tmp_path / "s.toml"
    scene.write_text("[[entities]]\nname = 'a'\n[entities.components.Transform]\n")
    app = App(scene, registry=reg, strict=True)
    app.step(2)
    assert order == [Stage.INPUT, Stage.SCRIPT, Stage.SIMULATION, Stage.POST_SIMULATION] * 2
    assert seen == [[0], [0, 1]]  # this tick's spawn is already there for the next system
