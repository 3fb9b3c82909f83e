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
