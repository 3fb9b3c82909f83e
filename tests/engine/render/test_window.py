"""The window front end, for real: a pyglet window on Xvfb (installed by `make test`'s set-up)."""

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
SCENE = "configs/scenes/sandbox.toml"


@pytest.fixture(scope="module")
def display():
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.fail("Xvfb is not installed: apt-get install -y xvfb (make test installs it when run as root)",
                    pytrace=False)
    for number in range(90, 120):
        if not Path(f"/tmp/.X11-unix/X{number}").exists() and not Path(f"/tmp/.X{number}-lock").exists():
            break
    proc = subprocess.Popen([xvfb, f":{number}", "-screen", "0", "1024x768x24"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    for _ in range(50):
        if Path(f"/tmp/.X11-unix/X{number}").exists():
            break
        time.sleep(0.1)
    yield f":{number}"
    proc.terminate()
    proc.wait(timeout=10)


def run(args, env):
    return subprocess.run([sys.executable, "-m", "engine", "run", SCENE, *args], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=300)


def test_window_run_matches_the_headless_hash_and_takes_screenshots(display, tmp_path):
    env = dict(os.environ, DISPLAY=display)
    shot = tmp_path / "window.png"
    shots = tmp_path / "every"
    window = run(["--steps", "30", "--hash", "--screenshot", str(shot), "--screenshot-every", "10", str(shots)], env)
    assert window.returncode == 0, window.stderr[-2000:]
    headless = run(["--no-render", "--steps", "30", "--hash"], dict(os.environ))
    assert window.stdout.strip().splitlines()[-1] == headless.stdout.strip().splitlines()[-1]
    from PIL import Image
    import numpy as np

    img = np.asarray(Image.open(shot))
    assert img.shape[:2] == (540, 960) and img.std() > 5  # a real picture, not a blank buffer
    assert len(list(shots.glob("*.png"))) == 3


SCRIPT = r"""
import pyglet
from pyglet.window import key, mouse
from engine.app import App
from engine.input import InputQueue
from engine.render.frontend import attach_window_input
import moderngl
from engine.render.renderer import Renderer

app = App("configs/scenes/sandbox.toml")
config = pyglet.gl.Config(red_size=8, green_size=8, blue_size=8, alpha_size=8, depth_size=24,
                          major_version=3, minor_version=3, forward_compatible=True)
window = pyglet.window.Window(320, 200, config=config, visible=True)
ctx = moderngl.create_context()
renderer = Renderer(app, ctx, 320, 200, screen=ctx.detect_framebuffer())
queue = app.world.resource(InputQueue)
attach_window_input(window, queue, renderer)
window.dispatch_event("on_key_press", key.W, 0)
window.dispatch_event("on_key_press", key._1, 0)
window.dispatch_event("on_key_press", key.F3, 0)
window.dispatch_event("on_mouse_press", 10, 20, mouse.LEFT, 0)
window.dispatch_event("on_mouse_drag", 15, 22, 5, 2, mouse.LEFT, 0)
window.dispatch_event("on_key_release", key.W, 0)
window.dispatch_events()
print([(e.kind, e.key, e.x, e.y, e.dx, e.dy) for e in queue.events])
print("profiler", renderer.show_profiler)
window.close()
"""


def test_window_events_become_engine_input_events(display):
    env = dict(os.environ, DISPLAY=display)
    res = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, cwd=ROOT, env=env,
                         timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    events, profiler = res.stdout.strip().splitlines()[-2:]
    assert events == str([("key_down", "w", 0.0, 0.0, 0.0, 0.0), ("key_down", "1", 0.0, 0.0, 0.0, 0.0),
                          ("key_down", "f3", 0.0, 0.0, 0.0, 0.0), ("button_down", "left", 10, 20, 0.0, 0.0),
                          ("mouse_move", "", 15, 22, 5, 2), ("key_up", "w", 0.0, 0.0, 0.0, 0.0)])
    assert profiler == "profiler True"


DYNAMIC = r"""
import pyglet
from engine.app import App
from engine.render import frontend
from engine.render.renderer import Renderer

fed, scales = [], []
frame_time = Renderer.frame_time


def recording(self, seconds):
    fed.append(seconds)
    frame_time(self, seconds)
    scales.append(self.render_scale)


Renderer.frame_time = recording
app = App("configs/scenes/sandbox.toml")
render = app.config.render
render.dynamic_resolution, render.vsync, render.target_fps, render.min_render_scale = True, True, 240.0, 0.5
pyglet.clock.schedule_once(lambda dt: pyglet.app.exit(), 4.0)
frontend._run_window(app, (640, 400), None, None, None, False)
print("frames", len(fed), "first", fed[0], "busy", all(s is not None and s > 0 for s in fed[1:]))
print("scales", scales[0], min(scales))
"""


def test_the_window_loop_feeds_dynamic_resolution_the_frames_own_length(display):
    """The real-time window loop with vsync: dynamic resolution gets each frame's measured work (its drawing
    finished before the swap), and an unreachable target (240 fps at 640 x 400 on llvmpipe) lowers the scale to
    its minimum."""
    env = dict(os.environ, DISPLAY=display)
    res = subprocess.run([sys.executable, "-c", DYNAMIC], capture_output=True, text=True, cwd=ROOT, env=env,
                         timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    lines = res.stdout.strip().splitlines()
    frames = lines[-2].split()
    assert int(frames[1]) >= 20 and frames[-1] == "True", lines
    assert lines[-1] == "scales 1.0 0.5", lines
