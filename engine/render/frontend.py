"""Front ends: a pyglet window (moderngl on pyglet's context) or headless EGL, one rendering path.

``--headless`` forces EGL; without a display the engine picks EGL by itself and says so.
"""

from __future__ import annotations

import argparse
import logging
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING

import moderngl

from engine.input import InputEvent, InputQueue
from engine.render.renderer import Renderer

if TYPE_CHECKING:
    from engine.app import App
    from engine.registry import Registry

log = logging.getLogger("engine.render")
GL_PACKAGES = "libegl1 libegl-mesa0 libgl1-mesa-dri"
DEFAULT_HEADLESS_FRAMES = 300


class ContextError(RuntimeError):
    """No OpenGL context could be created."""


def has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def create_headless_context() -> moderngl.Context:
    """A standalone EGL context (Mesa llvmpipe on machines without a GPU), OpenGL 3.3 core or newer."""
    try:
        return moderngl.create_standalone_context(backend="egl", require=330)
    except Exception as exc:  # moderngl raises plain Exception subclasses from glcontext
        raise ContextError(f"cannot create a headless OpenGL context through EGL ({exc}). "
                           f"Install Mesa's EGL: apt-get install -y {GL_PACKAGES}") from None


def headless_renderer(app: App, width: int | None = None, height: int | None = None,
                      ctx: moderngl.Context | None = None) -> Renderer:
    """A renderer for ``app`` drawing offscreen: ``app.render_frame()`` draws a frame, ``read_image()`` returns it
    as a PIL image and ``save_screenshot(path)`` writes it; ``release()`` frees its GL objects.  The size defaults
    to the scene's ``[render]`` width and height; ``ctx``: a context to share (tests make one per session, see
    :func:`create_headless_context`), else a new EGL one."""
    s = app.config.render
    return Renderer(app, ctx or create_headless_context(), width or s.width, height or s.height)


def _screenshot_plan(app: App, args: argparse.Namespace, headless: bool):
    every = None
    if args.screenshot_every:
        every = (max(1, int(args.screenshot_every[0])), Path(args.screenshot_every[1]))
    last = args.screenshot
    if headless and every is None and last is None and args.steps is None:
        out = Path("out") / app.config.scene.name
        every, last = (60, out), out / "last.png"
    return every, last


def run_rendered(app: App, args: argparse.Namespace, steps: int | None) -> None:
    headless = bool(args.headless)
    if not headless and not has_display():
        log.info("no display found: rendering headless with EGL (llvmpipe when there is no GPU)")
        headless = True
    size = tuple(args.size) if args.size else (app.config.render.width, app.config.render.height)
    every, last = _screenshot_plan(app, args, headless)
    if headless:
        _run_headless(app, size, steps, every, last, args.profile)
    else:
        _run_window(app, size, steps, every, last, args.profile)


def _reloader(app: App):
    from engine.reload import HotReloader

    return HotReloader(app) if app.plan is not None else None


def _run_headless(app: App, size, steps, every, last, profile: bool) -> None:
    renderer = headless_renderer(app, *size)
    renderer.timer.enabled = profile
    frames = DEFAULT_HEADLESS_FRAMES if steps is None else steps
    written = []
    overlap = app.config.render.overlap_ticks
    if overlap and frames:
        app.step(1)
    for frame in range(1, frames + 1):
        # headless: one fixed tick per frame, so the run is exactly reproducible.  Overlapped, frame N draws
        # tick N while tick N + 1 runs (Renderer.draw): the same pictures and the same final state
        if overlap:
            app.render_frame(overlap=(lambda: app.step(1)) if frame < frames else None)
        else:
            app.step(1)
            app.render_frame()
        if every and frame % every[0] == 0:
            written.append(renderer.save_screenshot(every[1] / f"frame_{frame:05d}.png"))
    if frames == 0:
        app.render_frame()
    if last:
        written.append(renderer.save_screenshot(last))
    if written:
        log.info("headless run of %d frames: wrote %d screenshot(s), last %s", frames, len(written), written[-1])
    if profile:
        print(renderer.timer.report())
    renderer.release()


# --------------------------------------------------------------------- window
_BUTTONS = {1: "left", 2: "middle", 4: "right"}


def key_name(symbol: int) -> str:
    """pyglet key symbol -> the engine's key name ("w", "space", "f1", "1", ...)."""
    from pyglet.window import key

    name = key.symbol_string(symbol).lower()
    if name.startswith("_") and name[1:].isdigit():
        name = name[1:]
    return {"return": "enter", "lshift": "shift", "rshift": "shift", "lctrl": "ctrl", "rctrl": "ctrl"}.get(name, name)


def _run_window(app: App, size, steps, every, last, profile: bool) -> None:
    import pyglet

    config = pyglet.gl.Config(red_size=8, green_size=8, blue_size=8, alpha_size=8, depth_size=24,
                              double_buffer=True, major_version=3, minor_version=3, forward_compatible=True)
    window = pyglet.window.Window(size[0], size[1], caption=f"ecsfx - {app.config.scene.name}", resizable=True,
                                  config=config, vsync=app.config.render.vsync)
    ctx = moderngl.create_context()
    renderer = Renderer(app, ctx, *window.get_framebuffer_size(), screen=ctx.detect_framebuffer())
    renderer.timer.enabled = profile
    queue = app.world.resource(InputQueue)
    state = {"frames": 0, "last": time.perf_counter(), "poll": 0.0, "busy": None}
    reloader = _reloader(app)
    attach_window_input(window, queue, renderer, reloader)

    @window.event
    def on_resize(width, height):
        fw, fh = window.get_framebuffer_size()
        renderer.resize(fw, fh)
        renderer.screen = ctx.detect_framebuffer()

    @window.event
    def on_draw():
        now = time.perf_counter()
        dt, state["last"] = now - state["last"], now
        if reloader is not None and now - state["poll"] > 0.5:  # hot reload: poll the files twice a second
            state["poll"] = now
            reloader.poll()
        if steps is not None:
            app.step(1)
            app.render_frame()
        else:
            app.advance(dt, busy=state["busy"])
            if app.config.render.dynamic_resolution and app.config.render.vsync:
                # with vsync the interval between frames is rounded up to the display's refresh, which hides the
                # headroom dynamic resolution needs to see: it judges the frame's own length, its drawing finished
                # before the swap waits (engine/render/resolution.py)
                ctx.finish()
                state["busy"] = time.perf_counter() - now
            else:
                state["busy"] = None
        state["frames"] += 1
        if every and state["frames"] % every[0] == 0:
            renderer.save_screenshot(every[1] / f"frame_{state['frames']:05d}.png")
        if steps is not None and app.world.tick >= steps:
            pyglet.app.exit()  # leave the loop; the window closes below (closing inside on_draw breaks pyglet)

    @window.event
    def on_close():
        pyglet.app.exit()
        return True

    pyglet.app.run(interval=0)
    if last and renderer.frame_index:  # (a window closed before its first frame has nothing to write)
        renderer.save_screenshot(last)
    if profile:
        print(renderer.timer.report())
    renderer.release()
    window.close()


def attach_window_input(window, queue: InputQueue, renderer: Renderer, reloader=None) -> None:
    """Translate pyglet events into engine InputEvents (pyglet's y axis points up, as the engine's).

    F3 toggles the profiler overlay and F5 forces a config and shader reload; both are front-end actions, not
    game input, but they are still passed on so that game scripts may react.
    """

    def on_key_press(symbol, modifiers):
        name = key_name(symbol)
        if name == "f3":
            renderer.show_profiler = not renderer.show_profiler
            renderer.timer.enabled = renderer.show_profiler or renderer.timer.enabled
        if name == "f5":
            for error in renderer.reload_shaders():
                print(f"shader reload: {error}", flush=True)
            if reloader is not None:
                reloader.reload()
        queue.push(InputEvent("key_down", name))
        return True  # swallow Escape: games use it for pause; the close button quits

    def on_key_release(symbol, modifiers):
        queue.push(InputEvent("key_up", key_name(symbol)))

    def on_mouse_motion(x, y, dx, dy):
        queue.push(InputEvent("mouse_move", x=x, y=y, dx=dx, dy=dy))

    def on_mouse_drag(x, y, dx, dy, buttons, modifiers):
        queue.push(InputEvent("mouse_move", x=x, y=y, dx=dx, dy=dy))

    def on_mouse_press(x, y, button, modifiers):
        queue.push(InputEvent("button_down", _BUTTONS.get(button, str(button)), x=x, y=y))

    def on_mouse_release(x, y, button, modifiers):
        queue.push(InputEvent("button_up", _BUTTONS.get(button, str(button)), x=x, y=y))

    def on_mouse_scroll(x, y, scroll_x, scroll_y):
        queue.push(InputEvent("scroll", x=x, y=y, dy=scroll_y))

    window.push_handlers(on_key_press, on_key_release, on_mouse_motion, on_mouse_drag, on_mouse_press,
                         on_mouse_release, on_mouse_scroll)


def compiled_graph_dot(scene: str, dot: bool = True, registry: Registry | None = None) -> str:
    """Build a scene, declare one frame headless and return the compiled graph (Graphviz or a listing); ``registry``
    as for ``App`` (None: the scene's plugins)."""
    from engine.app import App

    app = App(scene, registry=registry)
    renderer = headless_renderer(app, 320, 180)
    app.step(1)
    renderer.extract(app.world)
    graph = renderer.declare()
    compiled = graph.compile()
    if dot:
        text = graph.to_dot()
    else:
        text = "\n".join([f"{i + 1}. {name}" for i, name in enumerate(compiled.order)]
                         + [f"culled: {name}" for name in compiled.culled])
    renderer.release()
    return text
