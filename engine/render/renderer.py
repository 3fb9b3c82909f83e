"""The renderer: views from cameras, the render graph per frame, HDR targets, tone mapping, composition.

One rendering path for both kinds of context (a pyglet window or headless EGL): every view renders
into pooled HDR (rgba16f) colour + depth targets, is tone-mapped into an LDR target, and the views are
composited into the persistent ``final`` image.  A window then blits ``final`` to the screen; headless
runs read it back for screenshots.  Rendering only reads the world (render-extract copies what passes
need), so a run with or without a renderer ends with the same state hash.
"""

from __future__ import annotations

import logging
import re
import sys
import time
from dataclasses import dataclass, replace
from collections.abc import Callable, Hashable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import moderngl
import numpy as np

from engine.render.components import Camera, Hud, look_at, projection, view_matrix, viewport_pixels
from engine.render.feature import OVERLAY, SKY, ColorLayer, RenderFeature, View
from engine.render.graph import RenderGraph, ResourcePool, TextureDesc
from engine.render.lighting import Lighting, follow_file
from engine.render.resolution import DynamicResolution
from engine.render.shadows import Shadow, fit_light, light_basis, light_boxes
from engine.spatial import Transform

if TYPE_CHECKING:
    from engine.app import App
    from engine.render.terrain_shadow import TerrainShadow
    from engine.world import World

log = logging.getLogger("engine.render")
SHADER_DIR = Path(__file__).parent / "shaders"
# GL_RENDERER names of software rasterisers (lower case): antialiasing "auto" leaves FXAA off on them
_SOFTWARE_RASTERISERS = ("llvmpipe", "softpipe", "swrast", "swiftshader", "software rasterizer")
HDR_FORMAT = "rgba16f"  # every view's HDR colour target and its kept static layer (rgba32f: demo 49.4 -> 51.6 ms)


# the [render] settings dynamic resolution depends on: a hot reload that changes one of them starts it again from the
# set scale; one that changes others (fog, sky colours) keeps the scale it found
_RESOLUTION_SETTINGS = ("dynamic_resolution", "target_fps", "min_render_scale", "render_scale",
                        "software_render_scale")


def _find_gl_flush() -> Callable[[], None]:
    """glFlush of the current context (moderngl has glFinish only).  A flush hands the queued commands to the
    GPU without waiting; llvmpipe starts rasterising them on its threads.  Without a GL library to call into,
    a no-op: the commands then run at the next wait, as before."""
    import ctypes
    import ctypes.util

    names = [ctypes.util.find_library("OpenGL"), "libOpenGL.so.0", ctypes.util.find_library("GL"), "libGL.so.1"]
    for name in names:
        if not name:
            continue
        try:
            flush = ctypes.CDLL(name).glFlush
        except (OSError, AttributeError):
            continue
        flush.restype, flush.argtypes = None, []
        return flush
    log.info("glFlush not found: the next ticks run after each frame instead of while it is drawn")
    return lambda: None


_gl_flush: Callable[[], None] | None = None


def gl_flush() -> None:
    """Flush the current GL context's queued commands (see :func:`_find_gl_flush`)."""
    global _gl_flush
    if _gl_flush is None:
        _gl_flush = _find_gl_flush()
    _gl_flush()


def _thread_busy_ns() -> int:
    """This thread's CPU time plus the time it waited runnable for a core (Linux ``schedstat``), in ns: wall
    time minus this is the time it was blocked, not counting other threads holding the cores.  Where there is no
    ``schedstat``, the CPU time alone."""
    try:
        with open("/proc/thread-self/schedstat", "rb") as f:
            run, queued = f.read().split()[:2]
        return int(run) + int(queued)
    except (OSError, ValueError):
        return time.thread_time_ns()


class PassTimer:
    """Per-pass timings: GL timer queries when profiling (exact GPU time), CPU time otherwise.

    With ``waits`` on (and ``gpu`` off) no pass is followed by a finish: each pass's wall time and the main
    thread's busy time during it (CPU plus waiting runnable for a core) are recorded, and their difference
    (:attr:`wait_totals`) is the time the main thread spent blocked in the driver.  On llvmpipe that is where
    a pass reads what queued passes draw (a sampled render target, a memory barrier): the raster threads must
    finish first, so these waits show where the frame's main thread and raster threads stop overlapping."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.enabled = False
        self.gpu = True
        self.waits = False
        self.last: dict[str, float] = {}  # pass -> milliseconds (last frame)
        self.totals: dict[str, float] = {}
        self.wait_totals: dict[str, float] = {}  # pass -> milliseconds blocked (``waits`` mode)
        self.frames = 0
        # one timer query per pass name, reused every frame (moderngl cannot release a query: a new one per pass
        # and frame leaked ~0.85 kB each, megabytes a minute with the profiler overlay on)
        self._queries: dict[str, moderngl.Query] = {}

    def reset(self) -> None:
        """Forget the figures gathered so far (a benchmark's next measurement starts here)."""
        self.totals.clear()
        self.wait_totals.clear()
        self.frames = 0

    def wrap(self, name: str, execute: Callable[[Any], None]) -> Callable[[Any], None]:
        def timed(pc: Any) -> None:
            if self.enabled and self.waits and not self.gpu:
                start, busy = time.perf_counter(), _thread_busy_ns()
                execute(pc)
                ms, busy_ms = (time.perf_counter() - start) * 1e3, (_thread_busy_ns() - busy) / 1e6
                self.wait_totals[name] = self.wait_totals.get(name, 0.0) + max(ms - busy_ms, 0.0)
            elif self.enabled and self.gpu:
                try:
                    query = self._queries.get(name)
                    if query is None:
                        query = self._queries[name] = self.ctx.query(time=True)
                    with query:
                        execute(pc)
                    ms = query.elapsed / 1e6
                except (moderngl.Error, AttributeError):
                    self.gpu = False
                    ms = self._cpu(execute, pc)
            else:
                ms = self._cpu(execute, pc)
            self.last[name] = ms
            self.totals[name] = self.totals.get(name, 0.0) + ms

        return timed

    def _cpu(self, execute: Callable[[Any], None], pc: Any) -> float:
        start = time.perf_counter()
        execute(pc)
        if self.enabled:
            self.ctx.finish()
        return (time.perf_counter() - start) * 1e3

    def report(self) -> str:
        if not self.frames:
            return "no frames rendered"
        kind = "GPU timer queries" if (self.enabled and self.gpu) else "CPU time"
        rows = sorted(self.totals.items(), key=lambda kv: -kv[1])
        lines = [f"per-pass time, mean over {self.frames} frame(s) ({kind}):"]
        lines += [f"  {name:<40s} {total / self.frames:8.3f} ms" for name, total in rows]
        return "\n".join(lines)

    def report_waits(self, top: int | None = None) -> str:
        """The ``waits`` mode's figures: per pass, its wall time and how much of it the main thread was blocked,
        the passes that waited longest first (``top`` of them), and the sums over every pass."""
        if not self.frames:
            return "no frames rendered"
        n = self.frames
        rows = sorted(self.totals.items(), key=lambda kv: -self.wait_totals.get(kv[0], 0.0))
        lines = [f"main thread blocked per pass, mean over {n} frame(s) (no finish between passes; wall, of it "
                 f"blocked):"]
        lines += [f"  {name:<40s} {total / n:8.3f} ms, blocked {self.wait_totals.get(name, 0.0) / n:7.3f} ms"
                  for name, total in rows[:top]]
        lines.append(f"  {'every pass':<40s} {sum(self.totals.values()) / n:8.3f} ms, blocked "
                     f"{sum(self.wait_totals.values()) / n:7.3f} ms")
        return "\n".join(lines)


@dataclass
class _ShadowMap:
    """A camera's kept shadow map and the key of what it holds (None: nothing drawn yet)."""

    texture: moderngl.Texture
    size: int
    key: tuple | None = None


@dataclass
class _StaticLayer:
    """A view's kept static layer (Renderer._plan_static_layer): HDR colour and depth, and the key they show."""

    color: moderngl.Texture
    depth: moderngl.Texture
    key: tuple | None = None  # set once the copy into the textures is made
    pending: tuple | None = None  # the key of the layer being stored this frame
    ldr: moderngl.Texture | None = None  # the layer tone-mapped (views presented at full size, see _partial_present)
    ldr_key: tuple | None = None  # (layer key, exposure) it was tone-mapped with

    @property
    def size(self) -> tuple[int, int]:
        return self.color.size


class _TimedGraph:
    """The graph as features see it: add_pass wraps each execute callback with the timer."""

    def __init__(self, graph: RenderGraph, timer: PassTimer) -> None:
        self._graph = graph
        self._timer = timer

    def add_pass(self, name: str, setup, execute, side_effect: bool = False) -> None:
        self._graph.add_pass(name, setup, self._timer.wrap(name, execute), side_effect=side_effect)

    def __getattr__(self, item: str) -> Any:
        return getattr(self._graph, item)


class Renderer:
    """Draws an :class:`~engine.app.App`'s world with the registered render features."""

    def __init__(self, app: App, ctx: moderngl.Context, width: int, height: int,
                 screen: moderngl.Framebuffer | None = None) -> None:
        self.app = app
        self.ctx = ctx
        self.screen = screen
        self.resolution = DynamicResolution()  # [render] dynamic_resolution: see frame_time
        self._drawn_scale: float | None = None  # the render scale of the last frame drawn (see draw)
        self.use_settings(app.config.render)
        self.width, self.height = int(width), int(height)
        self.time = 0.0
        self.frame_index = 0
        self._programs: dict[tuple, moderngl.Program] = {}  # by source (vertex, fragment, geometry, varyings)
        self._shared: set[tuple] = set()  # the sources of the programs handed out by program(): never replaced
        self._loaded: dict[tuple, moderngl.Program] = {}  # (directory, name, defines)
        # programs that reload_shaders replaced, released at a frame's end once no vertex array is made on them;
        # and per program, the references to its moderngl object when it was made (before any vertex array)
        self._retired: list[moderngl.Program] = []
        self._own_refs: dict[moderngl.Program, int] = {}
        self._computes: dict[tuple, moderngl.ComputeShader] = {}  # (directory, name, defines)
        self._framebuffers: dict[tuple, moderngl.Framebuffer] = {}
        self.fullscreen_vaos: dict[tuple, moderngl.VertexArray] = {}  # (fragment shader, defines): passes.py
        self.quad_buffer = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], np.float32).tobytes())
        self.graph = RenderGraph(ResourcePool(self._make_resource, self._free_resource))
        self.timer = PassTimer(ctx)
        self.views: list[View] = []
        self.show_profiler = False
        self.pending_overlap: Callable[[], None] | None = None  # App.render_frame's overlap, run by draw()
        self._data: list[Any] = []
        self.fps = 0.0
        self._last_draw: float | None = None
        self._final: moderngl.Texture | None = None
        # camera entity -> (kept picture, frame index and game time it was rendered) of a view rendered every N frames
        self._held: dict[int, tuple[moderngl.Texture, int, float]] = {}
        # camera entity -> its view's kept static layer; and what its view had last frame: the layer's key and
        # each feature's static key
        self._static: dict[int, _StaticLayer] = {}
        self._static_seen: dict[int, tuple[tuple | None, dict[str, Any]]] = {}
        self.static_layer_counts = {"drawn": 0, "stored": 0, "restored": 0}  # views per outcome (tests, profiling)
        # camera entity -> its view's sun shadow map (depth texture, compared when sampled) and what it holds
        self._shadow_maps: dict[int, _ShadowMap] = {}
        # the first terrain's shadow-height map (engine/render/terrain_shadow.py), set by the terrain feature's
        # extract each frame: the meshes and the grass receive it; None without terrain or with terrain_shadows off
        self.terrain_shadow = None
        self.shadow_draws = 0  # shadow maps drawn (tests: a still scene draws its map once)
        self.fold_color_layers = True  # a view's last colour layer is added in its tone map (_fold_layer)
        self._shader_generation = 0  # bumped by reload_shaders: kept pictures drawn with older shaders are stale
        self._final_fbo: moderngl.Framebuffer | None = None
        renderer_name = str(ctx.info.get("GL_RENDERER", "")).lower()
        self.software = any(name in renderer_name for name in _SOFTWARE_RASTERISERS)
        self._resize_final()
        from engine.render.passes import builtin_features

        factories = list(builtin_features()) + list(app.registry.render_features)
        self.features: list[RenderFeature] = [f(self) for f in factories]
        self._ordered = sorted(enumerate(self.features), key=lambda kv: (kv[1].phase, kv[0]))
        app.renderer = self

    # ------------------------------------------------------------------ services
    def program(self, vertex_shader: str, fragment_shader: str, geometry_shader: str | None = None,
                varyings: tuple[str, ...] = ()) -> moderngl.Program:
        """The program of these sources, compiled once and kept until :meth:`release` (a caller may keep it: it
        is never replaced or released by :meth:`reload_shaders`, even when :meth:`load_program` shares it)."""
        key = (vertex_shader, fragment_shader, geometry_shader, varyings or ())
        self._shared.add(key)
        return self._compiled(key)

    def _compiled(self, key: tuple) -> moderngl.Program:
        prog = self._programs.get(key)
        if prog is None:
            vertex_shader, fragment_shader, geometry_shader, varyings = key
            prog = self.ctx.program(vertex_shader=vertex_shader, fragment_shader=fragment_shader,
                                    geometry_shader=geometry_shader, varyings=varyings)
            self._programs[key] = prog
            self._own_refs[prog] = sys.getrefcount(prog.mglo)
        return prog

    def _vertex_arrays_on(self, prog: moderngl.Program) -> int:
        """How many vertex arrays made on ``prog`` are not released: each holds a reference to the program's
        moderngl object from ``ctx.vertex_array`` to ``release`` (moderngl's C code; a vertex array dropped
        without release keeps it for good).  tests/engine/render/test_shader_reload.py checks it."""
        return sys.getrefcount(prog.mglo) - self._own_refs[prog]

    def load_program(self, directory: str | Path, name: str, defines: tuple[str, ...] = ()) -> moderngl.Program:
        """``name.vert`` + ``name.frag`` (+ ``name.geom``) from ``directory``, read and compiled once (passes call
        this every frame: no file reads after the first); :meth:`reload_shaders` picks up edited files.

        ``defines``: a shader variant, each name ``#define``d in every stage after its ``#version`` line (a
        software rasteriser runs both sides of a branch, so features compile variants instead of testing
        uniforms).

        After :meth:`reload_shaders` this returns another program when the files changed: a feature that keeps a
        vertex array made on the program passes it through :func:`engine.render.passes.current_vao` before it
        draws (remade on the new program, the old one released), or it keeps drawing the old shader, which then
        stays alive for it."""
        key = (str(directory), name, tuple(defines))
        prog = self._loaded.get(key)
        if prog is not None:
            return prog
        directory = Path(directory)
        geom = directory / f"{name}.geom"

        def source(path: Path) -> str:
            return _with_defines(shader_source(path), defines)

        try:
            prog = self._compiled((source(directory / f"{name}.vert"), source(directory / f"{name}.frag"),
                                   source(geom) if geom.exists() else None, ()))
        except moderngl.Error as exc:
            variant = f" ({', '.join(defines)})" if defines else ""
            raise RuntimeError(f"shader '{name}'{variant} in {directory} failed to compile:\n{exc}") from None
        self._loaded[key] = prog
        return prog

    def load_compute(self, directory: str | Path, name: str, defines: tuple[str, ...] = ()) -> moderngl.ComputeShader:
        """``name.comp`` from ``directory`` (GL 4.3), read and compiled once per variant (``defines`` as in
        :meth:`load_program`, e.g. ``"POINT_SIDE 2"``); :meth:`reload_shaders` picks up edited files too."""
        key = (str(directory), name, tuple(defines))
        shader = self._computes.get(key)
        if shader is not None:
            return shader
        text = _with_defines(shader_source(Path(directory) / f"{name}.comp"), defines)
        try:
            shader = self.ctx.compute_shader(text)
        except moderngl.Error as exc:
            variant = f" ({', '.join(defines)})" if defines else ""
            raise RuntimeError(f"shader '{name}.comp'{variant} in {directory} failed to compile:\n{exc}") from None
        self._computes[key] = shader
        return shader

    def reload_shaders(self) -> list[str]:
        """Re-read every shader loaded by name (programs and compute shaders); a file that no longer compiles
        keeps its last good version.

        A program replaced by an edited file is retired: :meth:`load_program` and :meth:`program` no longer hand
        it out, and it is released at the end of a frame once no vertex array made on it is left (features
        remake theirs when they next draw, see :meth:`load_program`), so nothing draws with a released program.
        Compute shaders are not kept by features (they call :meth:`load_compute` each time): the old ones are
        released at once.

        Returns the compile errors (empty when all compiled).  F5 in the window calls this with the config reload.
        """
        errors = []
        self._shader_generation += 1
        replaced = []
        for key in list(self._loaded):
            old = self._loaded.pop(key)
            try:
                if self.load_program(*key) is not old:
                    replaced.append(old)
            except (RuntimeError, OSError) as exc:
                self._loaded[key] = old
                errors.append(str(exc))
        in_use = {id(prog) for prog in self._loaded.values()}
        for old in {id(prog): prog for prog in replaced}.values():
            source = next((key for key, prog in self._programs.items() if prog is old), None)
            if id(old) not in in_use and source is not None and source not in self._shared:  # else kept: another
                del self._programs[source]  # loaded variant or a caller of program() has it
                self._retired.append(old)
        for key in list(self._computes):
            old = self._computes.pop(key)
            try:
                self.load_compute(*key)
            except (RuntimeError, OSError) as exc:
                self._computes[key] = old
                errors.append(str(exc))
            else:
                old.release()
        return errors

    def framebuffer(self, color: moderngl.Texture | list | None, depth: moderngl.Texture | None = None
                    ) -> moderngl.Framebuffer:
        colors = [] if color is None else (list(color) if isinstance(color, (list, tuple)) else [color])
        key = (tuple(c.glo for c in colors), depth.glo if depth is not None else 0)
        fbo = self._framebuffers.get(key)
        if fbo is None:
            fbo = self.ctx.framebuffer(color_attachments=colors, depth_attachment=depth)
            self._framebuffers[key] = fbo
        return fbo

    def _make_resource(self, desc: TextureDesc) -> moderngl.Texture:
        size = (desc.width, desc.height)
        if desc.is_depth:
            depth = self.ctx.depth_texture(size)
            depth.compare_func = ""  # sampled as plain depth by passes that read it (soft particles, PBVR)
            return depth
        tex = self.ctx.texture(size, desc.components, dtype=desc.dtype)
        tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        tex.repeat_x = tex.repeat_y = False
        return tex

    def _free_resource(self, tex: moderngl.Texture) -> None:
        for key in [k for k in self._framebuffers if tex.glo in k[0] or tex.glo == k[1]]:
            self._framebuffers.pop(key).release()
        tex.release()

    # ---------------------------------------------------------------- frame size
    def resize(self, width: int, height: int) -> None:
        """Resize the targets (the pool drops the old sizes as they go idle)."""
        width, height = max(1, int(width)), max(1, int(height))
        if (width, height) != (self.width, self.height):
            self.width, self.height = width, height
            self._resize_final()
            self.graph.pool.clear()  # the old size's targets (nothing is checked out between frames)

    def _resize_final(self) -> None:
        if self._final is not None:
            self._free_resource(self._final)
        self._final = self.ctx.texture((self.width, self.height), 4)
        self._final_fbo = self.framebuffer(self._final)

    def terrain_shadow_in(self, view: View) -> TerrainShadow | None:
        """The terrain shadow that features receive in ``view``: :attr:`terrain_shadow`, or None where the view
        hides the terrain (Camera ``hide_features``: a feature hidden in a view casts no shadow there, as with the
        sun's shadow maps)."""
        return None if "terrain" in view.extra.get("hide", ()) else self.terrain_shadow

    def use_settings(self, settings) -> None:
        """Draw with the scene's ``[render]`` settings (engine.scene.RenderSettings; a hot reload passes the new
        ones): most are read every frame.  The light (sun, sky, ambient, fog) is the world's
        :class:`~engine.render.lighting.Lighting`: the light keys of ``settings`` that changed since the world last
        took them are written into it first (:func:`~engine.render.lighting.follow_file`: a reload's edit, a test's
        new sun), the others keep what scripts set; a world without one draws the settings' own light."""
        old, self.scene_settings = getattr(self, "scene_settings", None), settings
        if old is None or any(getattr(old, key) != getattr(settings, key) for key in _RESOLUTION_SETTINGS):
            self.resolution.reset()  # a new target frame rate or scale range: start again from the set scale
        world = self.app.world
        follow_file(world, settings)
        self._light = None  # derived again from the new settings
        self._use_light(world.try_resource(Lighting))

    def _use_light(self, light: Lighting | None) -> None:
        """Draw with ``light`` (None: the scene settings' own): :attr:`settings` (``sky_top``, ``sky_horizon``,
        ``fog_density``), :attr:`sun_direction` (unit), :attr:`sun_color` and :attr:`ambient` carry it for every
        reader.  Nothing is remade when it is the light in effect (features key their caches on these values)."""
        scene = self.scene_settings
        if light is None:
            light = Lighting.of(scene)
        if light == self._light:
            return
        self._light = light
        # the scene's settings object itself while the light is the file's (in-place edits of it stay live)
        self.settings = scene if light == Lighting.of(scene) else scene.model_copy(update=light.values())
        self.sun_direction = _unit(np.array(light.sun_direction, float)).astype(np.float32)
        self.sun_color = np.array(light.sun_color, np.float32)
        self.ambient = float(light.ambient)

    @property
    def set_render_scale(self) -> float:
        """The render settings' ``render_scale``, or ``software_render_scale`` on a software rasteriser when the
        scene sets one."""
        software_scale = self.settings.software_render_scale
        return software_scale if self.software and software_scale is not None else self.settings.render_scale

    @property
    def render_scale(self) -> float:
        """The fraction of their window size the views render at: :attr:`set_render_scale`, or less while
        ``[render] dynamic_resolution`` lowers it (:meth:`frame_time`)."""
        scale = self.set_render_scale
        lowered = self.resolution.scale
        return scale if lowered is None or not self.settings.dynamic_resolution else min(lowered, scale)

    def frame_time(self, seconds: float) -> None:
        """The real-time loop's measured length of the last frame (:meth:`engine.app.App.advance`).  With
        ``[render] dynamic_resolution`` the next frames' render scale follows it (engine/render/resolution.py):
        lowered while frames miss ``1 / target_fps``, raised back when the set scale would hold it."""
        s = self.settings
        if not s.dynamic_resolution:
            self.resolution.reset()
            return
        high = self.set_render_scale
        self.resolution.update(seconds, 1.0 / s.target_fps, min(s.min_render_scale, high), high)

    @property
    def antialiasing(self) -> bool:
        """Whether frames are anti-aliased (the render settings' ``antialiasing``; ``auto``: on a hardware GPU)."""
        mode = self.settings.antialiasing
        return (not self.software) if mode == "auto" else mode == "fxaa"

    @property
    def shadow_map_size(self) -> int:
        """Texels a side of the shadow maps: ``[render] shadow_map_size``, unset: 2048 on a hardware GPU, 1024 on
        a software rasteriser."""
        size = self.settings.shadow_map_size
        return int(size) if size is not None else (1024 if self.software else 2048)

    @property
    def soft_shadows(self) -> bool:
        """Whether receivers filter the shadow map with four taps (``shadow_filter``; ``auto``: on a GPU)."""
        mode = self.settings.shadow_filter
        return (not self.software) if mode == "auto" else mode == "soft"

    @property
    def final_texture(self) -> moderngl.Texture:
        return self._final

    # --------------------------------------------------------------------- views
    def build_views(self, world: World) -> list[View]:
        cams = []
        for entity, (cam, t) in world.query(Camera, Transform):
            if cam.config.enabled:
                cams.append((cam.config.priority, entity, cam, t))
        cams.sort(key=lambda c: (c[0], c[1]))
        views = []
        for i, (_, entity, cam, t) in enumerate(cams):
            views.append(self._view_for(f"view{i}", cam, view_matrix(t), t.position, t.forward(), entity, i == 0))
        if not views:
            eye = np.array([18.0, 14.0, 18.0])
            cam = Camera(_default_camera_config())
            fwd = _unit(-eye)
            views.append(self._view_for("view0", cam, look_at(eye, (0, 0, 0)), eye, fwd, 0, True))
        return views

    def _view_for(self, name: str, cam: Camera, view: np.ndarray, pos, fwd, entity: int, main: bool) -> View:
        cfg = cam.config
        rect = viewport_pixels(cfg.viewport, (self.width, self.height))
        proj = projection(cfg, rect[2], rect[3])
        fov = float(np.radians(cfg.fov)) if cfg.projection == "perspective" else 0.0
        scale = self.render_scale  # views render at this fraction of their window size; present upscales
        width, height = max(1, int(round(rect[2] * scale))), max(1, int(round(rect[3] * scale)))
        v = View(name, width, height, view.astype(np.float32), proj.astype(np.float32), np.asarray(pos, np.float32),
                 np.asarray(fwd, np.float32), cfg.near, cfg.far, fov, cfg.projection == "orthographic",
                 is_main=main, camera_entity=entity, pixel_scale=scale)
        v.extra["rect"] = rect
        v.extra["border"] = tuple(cfg.border_color)
        v.extra["hide"] = frozenset(cfg.hide_features)
        v.extra["interval"] = 1 if main else int(cfg.update_interval)
        v.extra["shadows"] = bool(cfg.shadows)
        return v

    # --------------------------------------------------------------------- frame
    def render(self, world: World) -> None:
        """Extract then draw (both stages at once; the app's systems call them separately)."""
        self.extract(world)
        self.draw()

    def extract(self, world: World) -> None:
        """Render-extract stage: copy what the passes need and build the views (reads the world only).  The
        world's light is taken here, before the features' extract: ticks that run while the frame draws
        (``overlap``) may change it, and the frame keeps the light it extracted."""
        self._use_light(world.try_resource(Lighting))
        self.time = world.tick * self.app.dt
        self._data = [f.extract(world) for f in self.features]
        self.views = self.build_views(world)

    def declare(self) -> RenderGraph:
        """Declare every pass of every view for the extracted frame (no GL work)."""
        data = self._data
        graph = self.graph
        graph.reset()
        timed = _TimedGraph(graph, self.timer)
        final = graph.import_resource("final", self._final, TextureDesc(self.width, self.height, "rgba8"))
        self._plan_held_views()
        live = set()
        for view in self.views:
            live.add(view.camera_entity)
            if view.extra.get("held") == "shown":  # its last picture is shown again: nothing to draw
                continue
            hidden = view.extra.get("hide", ())
            features = [(i, f) for i, f in self._ordered if f.phase < OVERLAY and f.name not in hidden]
            self._declare_shadow(timed, view, features, data)
            static = self._plan_static_layer(view, features, data)
            if static is None:
                self._declare_view_targets(timed, view)
            elif view.extra["static_layer"] == "restored":
                self._declare_static_restore(timed, view)
                # what the passes after the copy write into the view's colour, and where (write_view_color)
                view.extra["color_regions"], view.extra["restored_version"] = [], view.color.version
                view.extra["restored_depth"] = (view.depth.version, self._static[view.camera_entity].key)
            else:  # "stored": the static features first, then a copy of what they drew into the kept layer
                self._declare_view_targets(timed, view)
                for index, feature in static:
                    feature.add_passes(timed, view, data[index])
                self._declare_static_store(timed, view)
            for index, feature in features:
                if static is None or (index, feature) not in static:
                    feature.add_passes(timed, view, data[index])
        for camera in [c for c in self._static if c not in live]:  # cameras gone
            self._free_static(camera)
        for camera in [c for c in self._static_seen if c not in live]:
            del self._static_seen[camera]
        for camera in [c for c in self._shadow_maps if c not in live]:
            self._free_shadow(camera)
        for i, view in enumerate(self.views):
            final = self._declare_present(timed, final, view, first=i == 0)
        screen = replace(self.views[0], name="screen", width=self.width, height=self.height,
                         color=final, depth=None, extra={})
        for index, feature in self._ordered:
            if feature.phase == OVERLAY:
                feature.add_passes(timed, screen, data[index])
        return graph

    def reset_frame_clock(self) -> None:
        """Forget the last frame's time: the next frame does not count towards :attr:`fps` (the HUD shows
        ``--`` until two frames in a row are drawn).  For callers that draw frames far apart, such as a headless
        run taking a screenshot every few hundred ticks, whose frame rate would otherwise read as 0.3 fps."""
        self.fps = 0.0
        self._last_draw = None

    def draw(self, overlap: Callable[[], None] | None = None) -> None:
        """Render stage: declare, compile (cached) and execute the graph; present in a window.

        ``overlap`` (the next simulation ticks, :meth:`engine.app.App.render_frame`) runs once while the GPU
        draws: at the graph's first synchronisation point (the first pass that reads what an earlier one
        wrote, :attr:`~engine.render.graph.CompiledGraph.sync_pass`) the queued passes are flushed, so the
        GPU, or a software rasteriser's threads, draw them while the CPU runs ``overlap``.  The passes use
        only what render-extract copied, so the picture is the same as when the ticks run after the frame.
        """
        self.timer.last = {}  # this frame's passes only (pass names carry entity ids: despawned ones go)
        # a new render scale (dynamic resolution, or back to the set scale: new settings, the setting turned off):
        # the old size's targets are freed, as on a resize (nothing is checked out between frames)
        scale = self.render_scale
        if self._drawn_scale is not None and scale != self._drawn_scale:
            self.graph.pool.clear()
        self._drawn_scale = scale
        if overlap is None:
            self.declare().execute()
        else:
            def sync() -> None:
                gl_flush()
                overlap()

            self.declare().execute(on_sync=sync)
        now = time.perf_counter()
        if self._last_draw is not None:
            self.fps = 0.9 * self.fps + 0.1 / max(now - self._last_draw, 1e-6) if self.fps else 1.0 / (now - self._last_draw)
        self._last_draw = now
        self.timer.frames += 1
        self.frame_index += 1
        if self.screen is not None:
            self.ctx.copy_framebuffer(self.screen, self._final_fbo)
        self._release_retired()

    def _release_retired(self) -> None:
        """Release the programs :meth:`reload_shaders` replaced that no vertex array is made on any more (the
        features that drew this frame have remade theirs); the others wait for a later frame."""
        held = []
        for prog in self._retired:
            if self._vertex_arrays_on(prog):
                held.append(prog)
            else:
                del self._own_refs[prog]
                prog.release()
        self._retired = held

    def _declare_view_targets(self, graph, view: View) -> None:
        def setup(b):
            self._create_view_targets(b, view)

        hidden = view.extra.get("hide", ())
        background = any(f.fills_background and f.name not in hidden for f in self.features)

        def execute(pc):
            fbo = self.framebuffer(pc.get(view.color), pc.get(view.depth))
            fbo.use()
            if background:  # the sky writes every pixel left at depth 1: clear the depth only (~1 ms CPU less
                fbo.color_mask = (False, False, False, False)  # at 640 x 480 rgba16f on llvmpipe)
                fbo.clear(depth=1.0)
                fbo.color_mask = (True, True, True, True)
            else:
                fbo.clear(*self.settings.sky_horizon, 1.0, depth=1.0)

        graph.add_pass(f"clear.{view.name}", setup, execute)

    # ------------------------------------------------------------------ shadows
    def _declare_shadow(self, graph, view: View, features: list, data: list) -> None:
        """The view's sun shadow map this frame (``view.extra["shadow"]``, :class:`engine.render.shadows.Shadow`):
        fitted to the view (engine/render/shadows.py), drawn by a pass only when the light box or a caster
        changed, otherwise the kept map is read again.  No map without ``[render] shadows``, with the camera's
        ``shadows`` off, or without casters."""
        view.extra.pop("shadow", None)
        camera = view.camera_entity
        if not (self.settings.shadows and view.extra.get("shadows", True)):
            self._free_shadow(camera)
            return
        casters = [c for c in (f.shadow_casters(data[i]) for i, f in features) if c is not None]
        if not casters:
            self._free_shadow(camera)
            return
        size = self.shadow_map_size
        basis = light_basis(self.sun_direction)
        caster_boxes = light_boxes(basis, np.concatenate([np.asarray(c.boxes, np.float64).reshape(-1, 2, 3)
                                                          for c in casters]))
        light_view_proj, matrix, texel, extent = fit_light(view, basis, self.settings.shadow_distance, size,
                                                           float(caster_boxes[:, 0, 2].min()))
        key = (size, light_view_proj.tobytes(), tuple(c.key for c in casters))
        kept = self._shadow_maps.get(camera)
        if kept is None or kept.size != size:
            self._free_shadow(camera)
            texture = self.ctx.depth_texture((size, size))
            texture.compare_func = "<="  # sampler2DShadow: a comparison, filtered over 2 x 2 texels
            texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            texture.repeat_x = texture.repeat_y = False
            kept = self._shadow_maps[camera] = _ShadowMap(texture, size)
        handle = graph.import_resource(f"{view.name}.shadow_map", kept.texture, TextureDesc(size, size, "depth24"))
        if kept.key != key:
            written = []

            def setup(b):
                written.append(b.write(handle))

            def execute(pc):
                fbo = self.framebuffer(None, pc.get(handle))
                fbo.use()
                fbo.clear(depth=1.0)
                self.ctx.enable(moderngl.DEPTH_TEST)
                self.ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)  # both faces: open shapes (planes) cast too
                self.ctx.polygon_offset = (2.0, 4.0)  # slope-scaled depth bias against self-shadowing stripes
                try:
                    for caster in casters:
                        caster.draw(light_view_proj)
                finally:
                    self.ctx.polygon_offset = (0.0, 0.0)
                kept.key = key
                self.shadow_draws += 1

            graph.add_pass(f"shadow.{view.name}", setup, execute)
            handle = written[0]
        view.extra["shadow"] = Shadow(handle, matrix, light_view_proj, texel,
                                      float(self.settings.shadow_bias) * texel, float(self.settings.shadow_distance),
                                      size, self.soft_shadows, key, basis, caster_boxes, extent)

    def _free_shadow(self, camera: int) -> None:
        kept = self._shadow_maps.pop(camera, None)
        if kept is not None:
            self._free_resource(kept.texture)

    # ---------------------------------------------------------- static layer
    def _plan_static_layer(self, view: View, features: list, data: list) -> list | None:
        """The view's static layer this frame: the OPAQUE and SKY features whose static key
        (:meth:`RenderFeature.static_key`) is the one they had last frame, or None when the view is drawn as usual.

        The layer's key is the view's (camera matrices, size, light, sky colours, fog, hidden features, shader
        generation) plus those features' keys.  When the kept layer has this key it is copied back ("restored":
        one memory copy of colour and depth instead of the clear and the features' passes); when the key is
        the one of the previous frame the layer is drawn first and copied into the kept layer ("stored");
        otherwise (a moving camera) the frame is drawn as it would be without the cache ("drawn").  A feature
        whose key changes every frame (meshes that move) stays out of the layer and draws over it.  Drawn
        first, the sky fills the far pixels before the other opaque features cover some of them: they write
        their own colour and depth over it, so the picture is the same bits in all three cases.
        """
        camera = view.camera_entity
        if not self.settings.static_layer_cache:
            self._free_static(camera)  # switched off: the kept textures go back
            self._static_seen.pop(camera, None)
            return None
        last, before = self._static_seen.get(camera, (None, {}))
        now = {}
        static, keys = [], []
        for index, feature in features:
            if feature.phase > SKY:
                break
            key = feature.static_key(view, data[index])
            if key is None:
                continue
            now[feature.name] = key
            if feature.name in before and before[feature.name] == key:
                static.append((index, feature))
                keys.append((feature.name, key))
        key = (self._view_key(view), tuple(keys), self._shader_generation) if static else None
        self._static_seen[camera] = (key, now)
        kept = self._static.get(camera)
        size = (view.width, view.height)
        if key is None:
            outcome = "drawn"
        elif kept is not None and kept.key == key and kept.size == size:
            outcome = "restored"
        elif last == key:  # the same two frames running: worth keeping
            if kept is None or kept.size != size:
                self._free_static(camera)
                kept = self._static[camera] = _StaticLayer(
                    self._make_resource(TextureDesc(view.width, view.height, HDR_FORMAT)),
                    self._make_resource(TextureDesc(view.width, view.height, "depth24")))
            kept.key, kept.pending = None, key
            outcome = "stored"
        else:
            outcome = "drawn"
        view.extra["static_layer"] = outcome
        self.static_layer_counts[outcome] += 1
        return None if outcome == "drawn" else static

    def _view_key(self, view: View) -> tuple:
        s = self.settings
        return (view.width, view.height, view.view.tobytes(), view.proj.tobytes(), view.camera_pos.tobytes(),
                view.ortho, frozenset(view.extra.get("hide", ())), self.sun_direction.tobytes(),
                self.sun_color.tobytes(), self.ambient, tuple(s.sky_top), tuple(s.sky_horizon), s.fog_density)

    def _static_layer_resources(self, graph, view: View) -> tuple:
        kept = self._static[view.camera_entity]
        return (graph.import_resource(f"{view.name}.static_color", kept.color,
                                      TextureDesc(view.width, view.height, HDR_FORMAT)),
                graph.import_resource(f"{view.name}.static_depth", kept.depth,
                                      TextureDesc(view.width, view.height, "depth24")))

    def _declare_static_restore(self, graph, view: View) -> None:
        color, depth = self._static_layer_resources(graph, view)
        # the present tone-maps the kept colour itself when no pass draws into the restored colour (only a colour
        # layer folded into the tone map wrote it): then only the depth is copied (_present_source)
        restore = view.extra["restore"] = {"color": True, "kept_color": color}

        def setup(b):
            b.read(color)
            b.read(depth)
            self._create_view_targets(b, view)

        def execute(pc):
            if restore["color"]:
                self._copy_layer(pc, (color, depth), (view.color, view.depth))
            else:
                self._copy_layer(pc, (None, depth), (None, view.depth))

        graph.add_pass(f"static_restore.{view.name}", setup, execute)

    def _declare_static_store(self, graph, view: View) -> None:
        color, depth = self._static_layer_resources(graph, view)
        kept = self._static[view.camera_entity]

        stored = {}

        def setup(b):
            b.read(view.color)
            b.read(view.depth)
            stored["color"] = b.write(color)
            b.write(depth)

        def execute(pc):
            self._copy_layer(pc, (view.color, view.depth), (color, depth))
            kept.key = kept.pending  # valid only once the copy is made (a frame that raised keeps nothing)

        graph.add_pass(f"static_store.{view.name}", setup, execute, side_effect=True)
        if not self._presented_whole(view):
            return
        if kept.ldr is None:
            kept.ldr = self._make_resource(TextureDesc(view.width, view.height, "rgba8"))
        ldr = graph.import_resource(f"{view.name}.static_ldr", kept.ldr, TextureDesc(view.width, view.height, "rgba8"))
        exposure = self.settings.exposure

        def tonemap_setup(b):
            b.read(stored["color"])
            stored["ldr"] = b.write(ldr)

        def tonemap(pc):
            from engine.render.passes import tonemap_execute

            kept.ldr_key = None
            tonemap_execute(self, pc, view, stored["ldr"], source=stored["color"])
            kept.ldr_key = (kept.key, exposure)

        graph.add_pass(f"static_tonemap.{view.name}", tonemap_setup, tonemap, side_effect=True)

    def _presented_whole(self, view: View) -> bool:
        """Whether ``view`` is tone-mapped straight into the whole window image (one view at full scale, drawn
        every frame, not anti-aliased): the case :meth:`_partial_present` serves."""
        return (view.extra.get("held") is None and view.extra["rect"] == (0, 0, self.width, self.height)
                and (view.width, view.height) == (self.width, self.height) and not self.antialiasing)

    def _partial_present(self, view: View) -> tuple[int, int, int, int] | None:
        """The rectangle of ``view`` (pixels: x, y, width, height; possibly empty) that its present has to tone-map
        this frame, the rest being copied from its static layer's tone-mapped picture; None to tone-map it all.

        Only for a restored static layer (its pixels are the kept ones, bit for bit, until a pass writes over
        them) whose picture was tone-mapped with this exposure, in a view presented whole, and only when every
        pass that wrote the view's colour after the copy said where (:func:`engine.render.feature.write_view_color`):
        the union of those regions bounds every pixel that can differ from the kept picture.  A write without a
        region (``b.write(view.color)``) leaves the count short and the whole view is tone-mapped, as before.
        """
        if view.extra.get("static_layer") != "restored" or not self._presented_whole(view):
            return None
        kept = self._static.get(view.camera_entity)
        if kept is None or kept.ldr is None or kept.ldr_key != (kept.key, self.settings.exposure):
            return None
        regions = view.extra.get("color_regions", [])
        if len(regions) != view.color.version - view.extra["restored_version"] or any(r is None for r in regions):
            return None
        boxes = [(x, y, x + w, y + h) for x, y, w, h in regions if w > 0 and h > 0]
        if not boxes:
            return (0, 0, 0, 0)
        x0, y0 = max(min(b[0] for b in boxes), 0), max(min(b[1] for b in boxes), 0)
        x1, y1 = min(max(b[2] for b in boxes), view.width), min(max(b[3] for b in boxes), view.height)
        return (x0, y0, max(x1 - x0, 0), max(y1 - y0, 0))

    @staticmethod
    def _create_view_targets(b, view: View) -> None:
        """In a pass's setup: the view's HDR colour and depth targets, created and written by that pass."""
        view.color = b.write(b.create(f"{view.name}.hdr", TextureDesc(view.width, view.height, HDR_FORMAT)))
        view.depth = b.write(b.create(f"{view.name}.depth", TextureDesc(view.width, view.height, "depth24")))

    def _copy_layer(self, pc, source: tuple, target: tuple) -> None:
        """Colour and depth of ``source`` (handles) into ``target``'s: a blit of equal formats and sizes, which the
        driver makes a memory copy."""
        def get(handle):
            return None if handle is None else pc.get(handle)

        fbo = self.framebuffer(get(target[0]), get(target[1]))
        fbo.use()  # its own viewport and no scissor: a blit is clipped by the scissor test
        self.ctx.copy_framebuffer(fbo, self.framebuffer(get(source[0]), get(source[1])))

    def _free_static(self, camera: int) -> None:
        kept = self._static.pop(camera, None)
        if kept is not None:
            self._free_resource(kept.color)
            self._free_resource(kept.depth)
            if kept.ldr is not None:
                self._free_resource(kept.ldr)

    HELD_MAX_AGE = 0.25  # seconds of game time a kept picture may lag behind the world

    def _plan_held_views(self) -> None:
        """Mark the views rendered every N frames (``Camera.update_interval``): "rendered" into their kept picture
        this frame, or "shown" (the kept picture again).  A view renders when N frames have passed since its
        last picture, when that picture is older than :attr:`HELD_MAX_AGE` of game time (frames far apart:
        screenshots of a headless run, a machine at a few frames per second), and when it is missing or of
        another size (first frame, resize, a viewport change)."""
        live = set()
        for view in self.views:
            interval = view.extra.get("interval", 1)
            if interval <= 1:
                continue
            key = view.camera_entity
            live.add(key)
            tex, frame, when = self._held.get(key, (None, 0, 0.0))
            size = (view.width, view.height)
            if tex is None or tex.size != size:
                if tex is not None:
                    self._free_resource(tex)
                tex = self._make_resource(TextureDesc(view.width, view.height, "rgba8"))
                render = True
            else:
                render = (self.frame_index - frame >= interval or not 0.0 <= self.time - when <= self.HELD_MAX_AGE)
            if render:
                frame, when = self.frame_index, self.time
            self._held[key] = (tex, frame, when)
            view.extra["held"] = "rendered" if render else "shown"
            view.extra["held_texture"] = tex
        for key in [k for k in self._held if k not in live]:  # cameras gone or back to every frame
            self._free_resource(self._held.pop(key)[0])

    def _declare_present(self, graph, final, view: View, first: bool):
        """Tone-map ``view`` into its rectangle of the window image.

        At full scale the tone map writes the window image directly.  Below full scale (``render_scale``) the
        view is tone-mapped at its own size into an 8-bit target and then upscaled bilinearly: the display
        transform (ACES fit + gamma, ~4x the cost of a texture fetch per pixel on a software rasteriser) runs
        on scale² of the pixels, as upscalers do (they work on display-referred colour).
        """
        from engine.render.passes import present_execute, tonemap_execute

        out = {}
        x, y, w, h = view.extra["rect"]
        source = view.color
        held = view.extra.get("held")
        layer = self._fold_layer(view) if held != "shown" else None
        hdr = self._present_source(view, layer) if held != "shown" else None

        def read_color(b):  # the view's colour, and the textures of a colour layer folded into its tone map
            b.read(view.color)
            if hdr is not None:
                b.read(hdr)
            if layer is not None:
                b.read(layer.texture)

        antialiased = self.antialiasing

        def tonemap_setup(b):
            read_color(b)
            out["ldr"] = out["tonemapped"] = b.write(b.create(f"{view.name}.ldr",
                                                              TextureDesc(view.width, view.height, "rgba8")))

        if held is not None:  # tone-mapped into the kept picture when rendered; presented from it every frame
            kept_picture = graph.import_resource(f"{view.name}.held", view.extra["held_texture"],
                                                 TextureDesc(view.width, view.height, "rgba8"))
            out["ldr"] = kept_picture
            if held == "rendered" and antialiased:  # anti-aliased once, into the kept picture
                graph.add_pass(f"tonemap.{view.name}", tonemap_setup,
                               lambda pc: tonemap_execute(self, pc, view, out["tonemapped"], source=hdr, layer=layer))
                out["ldr"] = self._declare_antialias(graph, view, out["ldr"], kept_picture)
            elif held == "rendered":
                def held_setup(b):
                    read_color(b)
                    out["ldr"] = b.write(out["ldr"])

                graph.add_pass(f"tonemap.{view.name}", held_setup,
                               lambda pc: tonemap_execute(self, pc, view, out["ldr"], source=hdr, layer=layer))
            source = None
        elif (view.width, view.height) != (w, h) or antialiased:
            # tone-mapped at the view's size, anti-aliased there (before any upscaling), then presented
            graph.add_pass(f"tonemap.{view.name}", tonemap_setup,
                           lambda pc: tonemap_execute(self, pc, view, out["tonemapped"], source=hdr, layer=layer))
            if antialiased:
                out["ldr"] = self._declare_antialias(graph, view, out["ldr"])
            source = None

        region = self._partial_present(view) if source is not None else None
        view.extra["present_region"] = region  # tests, profiling: None when the whole view was tone-mapped
        kept_ldr = None
        if region is not None:  # the kept picture copied, the rest tone-mapped (see _partial_present)
            kept_ldr = graph.import_resource(f"{view.name}.static_ldr", self._static[view.camera_entity].ldr,
                                             TextureDesc(view.width, view.height, "rgba8"))

        def setup(b):
            if source is not None:
                read_color(b)
            else:
                b.read(out["ldr"])
            if kept_ldr is not None:
                b.read(kept_ldr)
            out["final"] = b.write(final)

        graph.add_pass(f"present.{view.name}", setup,
                       lambda pc: present_execute(self, pc, view, out["final"], first,
                                                  None if source is not None else out["ldr"],
                                                  kept=None if kept_ldr is None else (kept_ldr, region),
                                                  layer=layer if source is not None else None, source=hdr))
        return out["final"]

    def _declare_antialias(self, graph, view: View, ldr, target=None):
        """FXAA (shaders/fxaa.frag) of ``view``'s tone-mapped picture ``ldr`` into ``target`` (a handle; None: a new
        8-bit target of the view's size); returns the handle written."""
        from engine.render.passes import antialias_execute

        out = {}

        def setup(b):
            b.read(ldr)
            made = target if target is not None else b.create(f"{view.name}.aa",
                                                               TextureDesc(view.width, view.height, "rgba8"))
            out["aa"] = b.write(made)

        graph.add_pass(f"antialias.{view.name}", setup, lambda pc: antialias_execute(self, pc, ldr, out["aa"]))
        return out["aa"]

    def static_depth_key(self, view: View) -> Hashable | None:
        """The kept static layer's key when ``view``'s depth is, at this point of the frame's declaration, that
        layer's depth copied back and not written since (a restored frame, no later pass drawing depth); None
        otherwise.  The same key means the same depth, bit for bit: a feature may keep what it derives from the
        depth (a smaller copy, say) under this key and skip re-deriving it while the key stays."""
        restored = view.extra.get("restored_depth")  # (depth version after the restore, the layer's key)
        if restored is None or view.depth.version != restored[0]:
            return None
        return restored[1]

    def _present_source(self, view: View, layer: ColorLayer | None):
        """The kept static colour (a graph handle) when ``view``'s colour is its restored static layer untouched
        but for ``layer`` folded into the tone map: the tone map reads the kept picture and the restore copies
        only the depth (one full-size HDR copy fewer). None: the view's colour."""
        restore = view.extra.get("restore")  # set on restored frames only (_declare_static_restore)
        if restore is None:
            return None
        writes = view.color.version - view.extra["restored_version"]
        if writes != (1 if layer is not None else 0):
            return None
        restore["color"] = False
        return restore["kept_color"]

    def _fold_layer(self, view: View) -> ColorLayer | None:
        """The colour layer (:class:`engine.render.feature.ColorLayer`) that ``view``'s tone map applies instead of
        the pass that declared it: the last one declared, when no pass wrote the view's colour after it (and
        ``fold_color_layers`` is on). Marks it folded, so that pass draws nothing."""
        entry = view.extra.get("color_layer")
        if entry is None or not self.fold_color_layers:
            return None
        layer, version = entry
        if version != view.color:
            return None
        layer.folded = True
        return layer

    # ----------------------------------------------------------------- pictures
    def read_image(self):
        """The last frame as a PIL image (top row first).  Before the first frame there is none: RuntimeError
        (the window image would read as black)."""
        from PIL import Image

        if self.frame_index == 0:
            raise RuntimeError("no frame drawn yet: call app.render_frame() (or renderer.render(world)) first")
        raw = self._final_fbo.read(components=4)
        img = Image.frombytes("RGBA", (self.width, self.height), raw).transpose(Image.FLIP_TOP_BOTTOM)
        return img.convert("RGB")

    def save_screenshot(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.read_image().save(path)
        return path

    def release(self) -> None:
        for f in self.features:
            f.release()
        for tex, _, _ in self._held.values():
            self._free_resource(tex)
        self._held.clear()
        for camera in list(self._static):
            self._free_static(camera)
        self._static_seen.clear()
        for camera in list(self._shadow_maps):
            self._free_shadow(camera)
        self.graph.pool.clear()
        for fbo in self._framebuffers.values():
            fbo.release()
        self._framebuffers.clear()
        for prog in [*self._programs.values(), *self._retired]:
            prog.release()
        self._programs.clear()
        self._retired.clear()
        self._own_refs.clear()
        self._shared.clear()
        self._loaded.clear()
        for shader in self._computes.values():
            shader.release()
        self._computes.clear()
        for vao in self.fullscreen_vaos.values():
            vao.release()
        self.fullscreen_vaos.clear()
        for obj in (self._final, self.quad_buffer):
            if obj is not None:
                obj.release()
        self._final = self._final_fbo = None


def _with_defines(text: str, defines: tuple[str, ...]) -> str:
    """``text`` with ``#define <d>`` for each of ``defines`` after its ``#version`` line."""
    if not defines:
        return text
    version, rest = text.split("\n", 1)
    return "\n".join([version, *(f"#define {d}" for d in defines), rest])


_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.M)


def shader_source(path: Path, depth: int = 0) -> str:
    """Shader text with ``#include "file"`` lines expanded (own folder first, then the engine's shaders)."""
    text = path.read_text(encoding="utf-8")

    def expand(match: re.Match) -> str:
        for folder in (path.parent, SHADER_DIR):
            candidate = folder / match.group(1)
            if candidate.is_file() and depth < 8:
                return shader_source(candidate, depth + 1)
        raise FileNotFoundError(f"{path}: #include \"{match.group(1)}\" not found in {path.parent} or {SHADER_DIR}")

    return _INCLUDE.sub(expand, text)


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    return v / n if n > 0 else v


def _default_camera_config():
    from engine.render.components import CameraConfig

    return CameraConfig(controller="none")


def hud_of(world: World) -> Hud | None:
    return world.try_resource(Hud)
