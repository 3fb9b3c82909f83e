"""The demo: scene and presets validate, the autoplay wins deterministically, frames match references,
and the dust devil can be dragged with injected mouse events."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from engine.app import App
from engine.builtin import find_named
from engine.cli import validate_file
from engine.input import InputEvent, InputQueue
from engine.registry import default_registry
from engine.render.components import Camera
from engine.spatial import Transform
from game_demo.autoplay import AutoPilot
from game_demo.scripts.common import GameState
from tests.render_utils import assert_golden, render_app

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "configs" / "scenes" / "demo.toml"


def test_demo_scene_and_its_presets_validate():
    registry = default_registry()
    validate_file(SCENE, registry)
    plan_files = App(SCENE).plan.files
    assert len(plan_files) >= 5  # the scene and the presets it names
    for path in plan_files[1:]:
        validate_file(Path(path), registry)
    validate_file(ROOT / "configs" / "prefabs" / "smoke_puff.toml", registry)


def test_autoplay_wins_with_the_same_hash_in_two_processes(tmp_path):
    """The issue's command, ``python -m game_demo --headless --autoplay --seed S`` (screenshots of the run), and the
    same run without rendering, in two processes: both win and print the same state hash last (rendering reads
    the world only, and the autoplay's mouse works in the same window size: ``--size`` sets it for both)."""
    base = [sys.executable, "-m", "game_demo", "--autoplay", "--seed", "42", "--max-seconds", "90",
            "--size", "640", "360"]
    cmds = [base + ["--headless", "--screenshots", str(tmp_path / "shots")], base + ["--no-render"]]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
             for cmd in cmds]
    outs = [p.communicate(timeout=600) for p in procs]
    for proc, (out, err) in zip(procs, outs):
        assert proc.returncode == 0, f"autoplay did not win:\n{err[-2000:]}"
        assert "won" in err
    hashes = [out.strip().splitlines()[-1] for out, _ in outs]
    assert hashes[0] == hashes[1] and len(hashes[0]) == 32
    assert len(list((tmp_path / "shots").glob("frame_*.png"))) >= 1  # the headless run's screenshots


def _played(ticks: int) -> App:
    app = App(SCENE)
    app.pre_tick.append(AutoPilot(window=(app.config.render.width, app.config.render.height)))
    app.step(ticks)
    return app


def test_main_view_with_minimap_matches_reference():
    app = _played(60)
    image = render_app(app, 256, 144, frames=1)
    assert_golden(image, "demo_main")


def test_top_view_matches_reference():
    app = _played(60)
    world = app.world
    main = world.get(find_named(world, "main_camera"), Camera)
    main.config = main.config.model_copy(update={"enabled": False})
    top = world.get(find_named(world, "top_camera"), Camera)
    top.config = top.config.model_copy(update={"viewport": (0.0, 0.0, 1.0, 1.0)})
    image = render_app(app, 160, 160, frames=1)
    assert_golden(image, "demo_top")


def test_dragging_the_dust_devil_with_injected_mouse_events_moves_it():
    app = App(SCENE)
    app.step(1)
    world = app.world
    moved = _drag_devil(app, (-12.0, 8.0))
    chase = 3.0 * 6 * app.dt  # the chaser script's own drift over these ticks, at most
    assert np.hypot(moved[0] + 12.0, moved[2] - 8.0) < 0.5 + chase
    assert world.resource(GameState).phase == "playing"


def test_pause_stops_the_timer_and_the_dust_devil():
    """Esc pauses the game: the timer and the dust devil's drift towards the player both wait (scripts still run
    while the simulation is paused)."""
    app = App(SCENE)
    app.step(10)
    world = app.world
    devil = find_named(world, "dust_devil")
    queue = world.resource(InputQueue)
    queue.push(InputEvent("key_down", "escape"))
    queue.push(InputEvent("key_up", "escape"))
    app.step(1)
    state = world.resource(GameState)
    assert state.paused
    before, time_left = world.get(devil, Transform).position.copy(), state.time_left
    app.step(60)
    assert state.time_left == time_left
    assert np.array_equal(world.get(devil, Transform).position, before)


def _drag_devil(app: App, offset=(-12.0, 8.0)) -> np.ndarray:
    """Drag the dust devil in the top view by ``offset`` metres (x, z) with injected mouse events; returns how far
    it moved."""
    world = app.world
    devil = find_named(world, "dust_devil")
    start = world.get(devil, Transform).position.copy()
    pilot = AutoPilot(window=(app.config.render.width, app.config.render.height))
    top = find_named(world, "top_camera")
    p0 = pilot._to_pixels(world, top, start)
    p1 = pilot._to_pixels(world, top, start + np.array([offset[0], 0.0, offset[1]]))
    queue = world.resource(InputQueue)
    queue.push(InputEvent("mouse_move", x=p0[0], y=p0[1]))
    queue.push(InputEvent("button_down", "left", x=p0[0], y=p0[1]))
    app.step(1)
    for i in range(1, 5):
        x, y = p0[0] + (p1[0] - p0[0]) * i / 4, p0[1] + (p1[1] - p0[1]) * i / 4
        queue.push(InputEvent("mouse_move", x=x, y=y, dx=(p1[0] - p0[0]) / 4, dy=(p1[1] - p0[1]) / 4))
        app.step(1)
    queue.push(InputEvent("button_up", "left", x=p1[0], y=p1[1]))
    app.step(1)
    return world.get(devil, Transform).position - start


def test_a_paused_game_cannot_drag_the_dust_devil():
    app = App(SCENE)
    app.step(1)
    queue = app.world.resource(InputQueue)
    queue.push(InputEvent("key_down", "escape"))
    queue.push(InputEvent("key_up", "escape"))
    app.step(1)
    assert app.world.resource(GameState).paused
    assert np.array_equal(_drag_devil(app), np.zeros(3))  # moved 20 m while paused before
    queue.push(InputEvent("key_down", "escape"))
    queue.push(InputEvent("key_up", "escape"))
    app.step(1)
    assert np.hypot(*_drag_devil(app)[[0, 2]]) > 10.0  # playing again: the same drag moves it


def test_restart_keeps_the_window_input_queue_and_the_keys_held():
    """The window pushes its events into the InputQueue it got at start-up: after R it must still be the world's
    queue, and a key held through the restart keeps counting as held."""
    app = App(SCENE)
    app.step(2)
    queue = app.world.resource(InputQueue)  # what the window holds on to
    queue.push(InputEvent("key_down", "w"))
    app.step(10)
    queue.push(InputEvent("key_down", "r"))
    app.step(1)  # restarts at the end of this tick
    queue.push(InputEvent("key_up", "r"))
    assert app.world.resource(InputQueue) is queue
    player = find_named(app.world, "player")
    before = app.world.get(player, Transform).position.copy()
    app.step(30)
    moved = app.world.get(player, Transform).position - before
    assert np.hypot(moved[0], moved[2]) > 2.0  # W still held: the player walks (stood still before)
    queue.push(InputEvent("key_down", "escape"))  # and the next key still reaches the game
    app.step(1)
    assert app.world.resource(GameState).paused


def test_the_smoke_puff_waits_while_the_game_is_paused():
    """The puff's lifetime script counts game time: a pause freezes it with the smoke simulation."""
    from engine.builtin import Name
    from engine.prefab import PrefabLibrary

    app = App(SCENE)
    app.step(2)
    puff = PrefabLibrary.of(app).spawn(app.world, "smoke_puff", np.array([0.0, 1.0, 0.0]), ())
    app.step(1)
    assert app.world.try_get(puff, Name) is not None
    app.world.resource(InputQueue).push(InputEvent("key_down", "escape"))
    app.step(1)
    assert app.world.resource(GameState).paused
    app.step(int(5.0 / app.dt))  # longer than the puff's 3.5 s
    assert app.world.try_get(puff, Name) is not None  # removed during the pause before
    app.world.resource(InputQueue).push(InputEvent("key_up", "escape"))
    app.world.resource(InputQueue).push(InputEvent("key_down", "escape"))
    app.step(int(4.0 / app.dt))
    assert not app.world.resource(GameState).paused
    assert app.world.try_get(puff, Name) is None


def test_the_hud_pattern_is_the_beam_pattern_from_the_start():
    from components.energy_wave import PATTERN_PARAMETERS, EnergyWaveEmitter

    app = App(SCENE)
    app.step(2)
    state = app.world.resource(GameState)
    emitter = app.world.get(find_named(app.world, "player"), EnergyWaveEmitter)
    for key, value in PATTERN_PARAMETERS[state.pattern].items():
        assert getattr(emitter, key) == value  # the preset's A/E mix before, with the HUD saying "A"


def test_the_autoplay_reach_follows_the_scene_tuning():
    from game_demo.autoplay import danger_radius, fire_range
    from systems.energy_wave import configure

    app = App(SCENE)
    app.step(1)
    world = app.world
    assert fire_range(world) == pytest.approx(0.85 * 40.0)
    assert danger_radius(world) == pytest.approx(3.0 + 3.0 * 2.5)  # lose_radius + chaser speed x 2.5 s
    configure(world, find_named(world, "player"), beam_range=22.0)
    assert fire_range(world) == pytest.approx(0.85 * 22.0)
