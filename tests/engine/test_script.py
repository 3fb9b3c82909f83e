from dataclasses import dataclass

import pytest
from pydantic import Field

from engine.app import App
from engine.config import ConfigModel
from engine.registry import default_registry
from engine.schedule import Stage
from engine.script import Script, ScriptError, ScriptFailure, Scripts, make_slot, script


@dataclass
class Ping:
    n: int


@dataclass
class Counter:
    value: int = 0


@script("counter")
class CounterScript(Script):
    events = (Ping,)

    class Params(ConfigModel):
        step: int = Field(1, ge=1, le=10)

    def on_start(self):
        self.log = ["start"]

    def on_update(self, dt):
        self.ctx.get(Counter).value += self.params.step

    def on_event(self, event):
        self.log.append(f"ping{event.n}")

    def on_destroy(self):
        self.ctx.world.resource(list).append(("destroyed", self.ctx.entity))


@script("broken")
class Broken(Script):
    def on_update(self, dt):
        if self.ctx.tick == 2:
            raise ValueError("boom")
        self.ctx.get(Counter).value += 1


@script("spawns")
class Spawns(Script):
    def on_update(self, dt):
        child = self.ctx.spawn(Counter(100))
        assert not self.ctx.world.alive(child)  # deferred until the stage's sync point


def make_app(strict=False, *scripts_per_entity):
    registry = default_registry([])
    registry.add_scripts([CounterScript, Broken, Spawns])
    app = App(registry=registry, strict=strict)
    app.world.insert_resource([])
    entities = []
    for names in scripts_per_entity:
        e = app.world.spawn(Counter())
        slots = [make_slot(app.world, e, registry.script(n), registry.script(n).Params()) for n in names]
        app.world.add(e, Scripts(slots))
        entities.append(e)
    return app, entities


def test_hooks_params_and_events():
    app, (e,) = make_app(False, ["counter"])
    app.step(1)
    app.world.events.send(Ping(7))
    app.step(2)
    slot = app.world.get(e, Scripts).slots[0]
    assert app.world.get(e, Counter).value == 3
    assert slot.script.log == ["start", "ping7"]
    app.world.despawn(e)
    assert app.world.resource(list) == [("destroyed", e)]


def test_script_error_is_isolated_and_reported(caplog):
    app, (bad, good) = make_app(False, ["broken"], ["counter"])
    app.step(5)
    assert app.world.get(bad, Counter).value == 2  # ran ticks 0 and 1, raised at tick 2, then disabled
    assert app.world.get(good, Counter).value == 5  # the game went on
    failure = app.world.resource(__import__("engine.script", fromlist=["ScriptRuntime"]).ScriptRuntime).failures[0]
    assert isinstance(failure, ScriptFailure) and failure.script == "broken" and failure.entity == bad
    assert "ValueError: boom" in failure.error and "Traceback" in failure.traceback
    assert "script 'broken' on entity" in caplog.text


def test_strict_mode_reraises():
    app, _ = make_app(True, ["broken"])
    with pytest.raises(ScriptError, match="'broken' on entity 1 raised in on_update: boom"):
        app.step(5)


def test_spawn_from_script_applies_at_sync_point():
    app, (e,) = make_app(True, ["spawns"])
    app.step(1)
    assert len(app.world.query(Counter)) == 2
    app.step(1)
    assert len(app.world.query(Counter)) == 3


def test_plugin_command_called_from_script():
    registry = default_registry([])
    calls = []
    registry.add_command("test.fire", lambda world, entity, power: calls.append((entity, power)) or power * 2)

    @script("caller")
    class Caller(Script):
        def on_update(self, dt):
            self.result = self.ctx.call("test.fire", power=3)

    registry.add_script(Caller)
    app = App(registry=registry, strict=True)
    e = app.world.spawn()
    app.world.add(e, Scripts([make_slot(app.world, e, Caller, Caller.Params())]))
    app.step(1)
    assert calls == [(e, 3)] and app.world.get(e, Scripts).slots[0].script.result == 6


def test_schedule_print_order(capsys):
    from engine.cli import main

    assert main(["run", "configs/scenes/sandbox.toml", "--print-schedule"]) == 0
    out = capsys.readouterr().out
    assert out.index("core.input") < out.index("core.scripts") < out.index("render.draw")


def test_render_commands_and_the_window_size_from_scripts(tmp_path):
    """render.camera changes another camera's config, validated like the TOML (a bad value names the field and
    keeps the camera); render.hud sets only the fields given; ctx.window_size is the scene's size without a
    renderer."""
    from engine.config import ConfigError
    from engine.render.components import Camera, Hud
    from engine.script import ScriptContext

    scene = tmp_path / "cams.toml"
    scene.write_text('[scene]\nplugins = ["render"]\n[render]\nwidth = 320\nheight = 200\n'
                     '[[entities]]\nname = "cam"\n[entities.components.Transform]\n[entities.components.Camera]\n',
                     encoding="utf-8")
    app = App(scene)
    cam = next(e for e, _ in app.world.query(Camera))
    other = app.world.spawn()
    ctx = ScriptContext(app.world, other, "test")
    assert ctx.window_size == (320, 200)
    config = ctx.call("render.camera", camera=cam, viewport=(0.5, 0.0, 0.5, 1.0), update_interval=3)
    assert app.world.get(cam, Camera).config is config
    assert config.viewport == (0.5, 0.0, 0.5, 1.0) and config.update_interval == 3
    with pytest.raises(ConfigError, match="update_interval"):
        ctx.call("render.camera", camera=cam, update_interval=0, viewport=(0.0, 0.0, 1.0, 1.0))
    assert app.world.get(cam, Camera).config is config  # unchanged
    ctx.call("render.hud", lines=["a"], show_fps=True)
    ctx.call("render.hud", show_help=True)
    hud = app.world.resource(Hud)
    assert hud.lines == ["a"] and hud.show_fps and hud.show_help


def test_a_script_error_names_the_scene_file_and_key(tmp_path, caplog):
    """A script declared in a scene that raises at run time names where it was declared, so a modder knows which
    file and entry to fix (it named only the script and the entity id)."""
    @script("raises")
    class Raises(Script):
        def on_update(self, dt):
            raise ValueError("boom")

    registry = default_registry([])
    registry.add_script(Raises)
    path = tmp_path / "configs" / "scenes" / "s.toml"
    path.parent.mkdir(parents=True)
    path.write_text('[[entities]]\nname = "a"\n\n[[entities]]\nname = "b"\nscripts = [{ name = "raises" }]\n')
    app = App(path, registry=registry)
    app.step(1)
    assert f"{path}: entities[1].scripts[0]: script 'raises' on entity 2 ('b') raised in on_update" in caplog.text
    strict = App(path, registry=registry, strict=True)
    with pytest.raises(ScriptError, match=r"entities\[1\]\.scripts\[0\]: script 'raises' on entity 2 \('b'\) "
                                          r"raised in on_update: boom"):
        strict.step(1)


def test_context_reaches_other_entities_resources_and_the_ground(tmp_path):
    """The scripting API a game needs for other entities (find by name, their components), shared state (a
    resource that is part of the state hash) and the terrain's height, without reaching into ctx.world."""
    import numpy as np

    from engine.builtin import Terrain
    from engine.script import ScriptContext
    from engine.spatial import Transform

    scene = tmp_path / "s.toml"
    scene.write_text("[[entities]]\nname = 'me'\n[entities.components.Transform]\n"
                     "[[entities]]\nname = 'ground'\n[entities.components.Transform]\nposition = [0.0, 2.0, 0.0]\n"
                     "[entities.components.Terrain]\nsize_exponent = 3\n"
                     "[[entities]]\nname = 'crate'\n[entities.components.Transform]\nposition = [1.0, 5.0, 2.0]\n")
    app = App(scene, strict=True)
    me = 1
    ctx = ScriptContext(app.world, me, "test")
    crate = ctx.find("crate")
    assert crate is not None and crate != me and ctx.find("nobody") is None
    assert np.array_equal(ctx.get(Transform, crate).position, [1.0, 5.0, 2.0])
    assert ctx.try_get(Terrain, crate) is None and ctx.try_get(Terrain, ctx.find("ground")) is not None
    assert ctx.get(Transform) is app.world.get(me, Transform)
    expected = app.world.get(ctx.find("ground"), Terrain).field.height_at(np.array([3.0]), np.array([-1.0]))[0] + 2.0
    assert ctx.ground_height(3.0, -1.0) == pytest.approx(expected)

    @dataclass
    class Score:
        points: int = 0

    before = app.state_hash()
    assert ctx.try_resource(Score) is None
    ctx.insert_resource(Score(7))
    assert ctx.resource(Score).points == 7
    assert app.state_hash() != before  # shared script state is game state by default
    ctx.despawn(crate)
    app.world.commands.apply()
    assert not ctx.alive(crate) and ctx.find("crate") is None


def test_a_script_keeping_something_that_is_not_state_is_named_when_hashing(tmp_path):
    """A script that stores a generator (or the world) cannot be hashed; the error says where: the entity, the
    script's class and the attribute, and how to keep it out (was a bare 'cannot hash state of type generator')."""
    from engine.state import StateHashError

    @script("test.keeps_a_generator")
    class KeepsAGenerator(Script):
        def on_start(self) -> None:
            self.counter = 3
            self.ticks = (i for i in range(10))

    reg = default_registry()
    reg.add_script(KeepsAGenerator)
    scene = tmp_path / "s.toml"
    scene.write_text("[[entities]]\nname = 'hero'\nscripts = [{ name = 'test.keeps_a_generator' }]\n")
    app = App(scene, registry=reg, strict=True)
    app.step(1)
    with pytest.raises(StateHashError) as err:
        app.state_hash()
    text = str(err.value)
    assert "type generator at entity 1 ('hero') Scripts.slots[0] (ScriptSlot)[3] (KeepsAGenerator).ticks" in text
    assert "__hash_state__" in text


def test_a_script_keeping_the_world_is_a_state_hash_error_not_a_recursion_error(tmp_path):
    """The world refers to itself (its command buffer): hashing it alone was a RecursionError with no path; now the
    cycle is named. Kept by a script, the error names the script's attribute."""
    from engine.state import StateHashError, digest
    from engine.world import World

    @script("test.keeps_the_world")
    class KeepsTheWorld(Script):
        def on_start(self) -> None:
            self.kept = self.ctx.world

    reg = default_registry()
    reg.add_script(KeepsTheWorld)
    scene = tmp_path / "s.toml"
    scene.write_text("[[entities]]\nname = 'hero'\nscripts = [{ name = 'test.keeps_the_world' }]\n")
    app = App(scene, registry=reg, strict=True)
    app.step(1)
    with pytest.raises(StateHashError) as err:
        app.state_hash()
    assert "(KeepsTheWorld).kept" in str(err.value)
    with pytest.raises(StateHashError, match="World .it contains itself."):
        digest(World(0))
    app.step(1)  # the failed hash left nothing behind: hashing state without the cycle works again
    assert len(digest({"a": [1.0, 2.0]})) == 32


def test_commands_name_other_entities_by_id_or_name_and_bad_arguments_say_what_the_command_takes(tmp_path):
    """Every command that acts on another entity takes its id or its scene name (rigid_body.apply_impulse took
    only an int: target="crate" was int('crate')); a wrong keyword names the command and its parameters; a
    single string for the HUD's lines is refused (it showed one letter per line)."""
    import numpy as np

    from engine.script import ScriptContext
    from components.water_surface import RigidBodyState

    scene = tmp_path / "s.toml"
    scene.write_text("[[entities]]\nname = 'me'\n[entities.components.Transform]\n"
                     "[[entities]]\nname = 'crate'\n[entities.components.Transform]\n"
                     "[entities.components.RigidBody]\nshape = 'box'\nhalf_extents = [0.5, 0.5, 0.5]\n")
    app = App(scene, strict=True)
    ctx = ScriptContext(app.world, 1, "test")
    crate = ctx.find("crate")
    ctx.call("rigid_body.apply_impulse", impulse=(0.0, 100.0, 0.0), target="crate")
    assert app.world.get(crate, RigidBodyState).impulse[1] == 100.0  # applied at the next step
    with pytest.raises(ValueError, match="target: no entity named 'crat'; did you mean 'crate'"):
        ctx.call("rigid_body.apply_impulse", impulse=(0.0, 1.0, 0.0), target="crat")
    with pytest.raises(TypeError, match=r"command 'rigid_body.apply_impulse': .*'speed'.*; it takes \(impulse"):
        ctx.call("rigid_body.apply_impulse", impulse=(0.0, 1.0, 0.0), speed=3)
    with pytest.raises(ValueError, match="lists of strings"):
        ctx.call("render.hud", lines="hello")
    assert app.world.get(crate, RigidBodyState).impulse[1] == 100.0  # the refused calls changed nothing
