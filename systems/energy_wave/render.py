"""The energy-wave render feature: additive billboards expanded on the GPU, plus a glow (bloom) pass.

Per frame, :func:`~systems.energy_wave.extract.extract_frame` packs one record per particle; they are uploaded to
an RGBA32F texture (three texels a record) and drawn as quads of two triangles with no vertex buffer: per emitter,
one draw for single sprites, one for trails (6 × particles × M vertices) and one for bars (6 × particles × N);
the vertex shader finds its particle, sub-sprite and corner from ``gl_VertexID`` (eqs. 3.7–3.9). (Not instanced:
llvmpipe runs its vertex pipeline once per instance, a fixed cost that made up most of the vertex work.) Blending is additive (ONE, ONE), depth-tested against
the scene with no depth writes, so no sorting is needed.

Passes per view, in the transparent phase (off-screen particles, Nguyen, GPU Gems 3 ch. 23: the soft sprites are
fill-rate bound, so they are drawn at half resolution):
``energy_wave.sprites.<view>``: every sprite, additively, into a half-resolution HDR buffer; occlusion is the depth
test against the view's depth texture, done in the fragment shader (no depth writes);
``energy_wave.glow_blur_x/y.<view>``: a separable Gaussian blur of that buffer at quarter resolution (bloom);
``energy_wave.composite.<view>``: buffer + glow strength × blurred buffer, added onto the view's HDR colour.
The glow of a frame uses the largest ``glow`` and ``glow_radius`` among the emitters.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import moderngl
import numpy as np

from engine.render.feature import TRANSPARENT, RenderFeature, View
from engine.render.graph import TextureDesc

from .extract import BAR, RECORD_FLOATS, SINGLE, TRAIL, FrameData, extract_frame

if TYPE_CHECKING:
    from engine.render.renderer import Renderer
    from engine.world import World

SHADERS = Path(__file__).parent / "shaders"
RECORDS_PER_ROW = 1024
PARTICLE_DOWNSCALE = 2  # sprites are drawn at half the view's resolution (off-screen particles), then upsampled
GLOW_DOWNSCALE = 4
VERTICES_PER_SPRITE = 6  # two triangles


def radial_gradient(r2: np.ndarray) -> np.ndarray:
    """The sprite's falloff at squared distance ``r2`` from its centre (sprite radius 1): (1 - r²)² · exp(-3 r²)
    inside, 0 outside; ``particles.frag`` evaluates the same formula per fragment."""
    r2 = np.asarray(r2, dtype=np.float64)
    return np.where(r2 < 1.0, (1.0 - r2) ** 2 * np.exp(-3.0 * r2), 0.0)


def _set(prog: moderngl.Program, **values) -> None:
    for name, value in values.items():
        if name in prog:
            prog[name].value = value


class EnergyWaveFeature(RenderFeature):
    """Draws every EnergyWaveEmitter's particles (section 3.4 of seeds/000)."""

    name = "energy_wave"
    phase = TRANSPARENT

    def __init__(self, renderer: Renderer) -> None:
        super().__init__(renderer)
        self._records: moderngl.Texture | None = None
        self._rows = 0
        self._uploaded_frame = -1
        self._staging = np.zeros((0, RECORD_FLOATS), np.float32)  # the upload's whole rows, reused
        self._vao: moderngl.VertexArray | None = None
        self._fullscreen: dict[str, moderngl.VertexArray] = {}

    # ------------------------------------------------------------------------------------------ extraction
    def extract(self, world: World) -> FrameData:
        return extract_frame(world)

    # ------------------------------------------------------------------------------------------- GL objects
    def _program(self, name: str) -> moderngl.Program:
        return self.renderer.load_program(SHADERS, name)

    def _sprite_vao(self) -> moderngl.VertexArray:
        if self._vao is None:
            self._vao = self.ctx.vertex_array(self._program("particles"), [])  # corners from gl_VertexID
        return self._vao

    def _fullscreen_vao(self, name: str) -> moderngl.VertexArray:
        vao = self._fullscreen.get(name)
        if vao is None:
            vao = self.ctx.vertex_array(self._program(name), [])
            self._fullscreen[name] = vao
        return vao

    def _upload(self, data: FrameData) -> None:
        """Records into the RGBA32F texture (once per frame, shared by every view)."""
        if self._uploaded_frame == self.renderer.frame_index:
            return
        self._uploaded_frame = self.renderer.frame_index
        n = len(data.records)
        rows = max(1, -(-n // RECORDS_PER_ROW))
        if self._records is None or rows > self._rows:
            if self._records is not None:
                self._records.release()
            self._rows = 1 << (rows - 1).bit_length()
            self._records = self.ctx.texture((RECORDS_PER_ROW * 3, self._rows), 4, dtype="f4")
            self._records.filter = (moderngl.NEAREST, moderngl.NEAREST)
        if len(self._staging) < rows * RECORDS_PER_ROW:
            self._staging = np.zeros((self._rows * RECORDS_PER_ROW, RECORD_FLOATS), np.float32)
        staging = self._staging[: rows * RECORDS_PER_ROW]
        staging[:n] = data.records
        staging[n:] = 0.0  # the tail of the last row (never drawn)
        self._records.write(staging, viewport=(0, 0, RECORDS_PER_ROW * 3, rows))

    # ---------------------------------------------------------------------------------------------- drawing
    def _draw_sprites(self, view: View, data: FrameData) -> None:
        vao = self._sprite_vao()
        prog = vao.program
        self._records.use(0)
        view_m = view.view.astype(np.float64)
        _set(prog, records=0, scene_depth=2, records_per_row=RECORDS_PER_ROW,
             camera_right=tuple(map(float, view_m[0, :3])), camera_up=tuple(map(float, view_m[1, :3])),
             depth_scale=float(PARTICLE_DOWNSCALE))
        prog["view_proj"].write(view.view_proj.T.astype(np.float32).tobytes())
        for emitter in data.emitters:
            cfg = emitter.config
            if cfg.intensity <= 0.0:
                continue
            _set(prog, size=cfg.particle_size, spacing=cfg.bar_spacing * cfg.particle_size,
                 roundness=cfg.splash_roundness, trail_end=cfg.trail_end_scale, color=tuple(cfg.color),
                 core_color=tuple(cfg.core_color), intensity=cfg.intensity)
            first = emitter.first
            groups = ((SINGLE, 0, 1), (TRAIL, 1, cfg.trail_textures), (BAR, 2, cfg.splash_samples))
            for group, mode, sprites in groups:  # three draws per emitter, whatever M and N
                count = emitter.counts[group]
                if count:
                    _set(prog, first=first, mode=mode, sprites=sprites)
                    vao.render(moderngl.TRIANGLES, vertices=VERTICES_PER_SPRITE * count * sprites)
                first += count

    def add_passes(self, graph, view: View, data: FrameData) -> None:
        if data is None or not data.emitters or len(data.records) == 0:
            return  # nothing alive: no passes, no full-screen composite
        ctx = self.ctx
        size = (max(1, view.width // PARTICLE_DOWNSCALE), max(1, view.height // PARTICLE_DOWNSCALE))
        glow_size = (max(1, view.width // GLOW_DOWNSCALE), max(1, view.height // GLOW_DOWNSCALE))
        glow = max(e.config.glow for e in data.emitters)
        radius = max(e.config.glow_radius for e in data.emitters)
        h: dict[str, object] = {}

        def sprites_setup(b):
            b.read(view.depth)
            h["particles"] = b.write(b.create(f"energy_wave.{view.name}.particles",
                                              TextureDesc(size[0], size[1], "rgba16f")))

        def sprites_execute(pc):
            self._upload(data)
            fbo = self.renderer.framebuffer(pc.get(h["particles"]))
            fbo.use()
            fbo.clear(0.0, 0.0, 0.0, 0.0)
            depth = pc.get(view.depth)
            compare = depth.compare_func
            depth.compare_func = ""  # read depth values, not shadow comparisons
            depth.use(2)
            ctx.disable(moderngl.DEPTH_TEST)  # depth tested against the view's depth in the shader; no writes
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = moderngl.ONE, moderngl.ONE
            try:
                self._draw_sprites(view, data)
            finally:
                depth.compare_func = compare
                ctx.blend_func = moderngl.DEFAULT_BLENDING
                ctx.disable(moderngl.BLEND)

        def blur(src_key: str, dst_key: str, axis: int):
            def setup(b):
                b.read(h[src_key])
                h[dst_key] = b.write(b.create(f"energy_wave.{view.name}.{dst_key}",
                                              TextureDesc(glow_size[0], glow_size[1], "rgba16f")))

            def execute(pc):
                fbo = self.renderer.framebuffer(pc.get(h[dst_key]))
                fbo.use()
                ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
                vao = self._fullscreen_vao("glow_blur")
                pc.get(h[src_key]).use(0)
                step = [0.0, 0.0]
                step[axis] = (radius / 4.0) / glow_size[axis]
                _set(vao.program, source=0, step_uv=tuple(step))
                vao.render(moderngl.TRIANGLES, vertices=3)

            return setup, execute

        def composite_setup(b):
            b.read(h["particles"])
            if glow > 0.0:
                b.read(h["blur_y"])
            view.color = b.write(view.color)

        def composite_execute(pc):
            fbo = self.renderer.framebuffer(pc.get(view.color))
            fbo.use()
            ctx.disable(moderngl.DEPTH_TEST)
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = moderngl.ONE, moderngl.ONE
            try:
                vao = self._fullscreen_vao("composite")
                pc.get(h["particles"]).use(0)
                pc.get(h["blur_y"] if glow > 0.0 else h["particles"]).use(1)
                _set(vao.program, particles=0, glow=1, glow_strength=float(glow))
                vao.render(moderngl.TRIANGLES, vertices=3)
            finally:
                ctx.blend_func = moderngl.DEFAULT_BLENDING
                ctx.disable(moderngl.BLEND)

        graph.add_pass(f"energy_wave.sprites.{view.name}", sprites_setup, sprites_execute)
        if glow > 0.0:
            graph.add_pass(f"energy_wave.glow_blur_x.{view.name}", *blur("particles", "blur_x", 0))
            graph.add_pass(f"energy_wave.glow_blur_y.{view.name}", *blur("blur_x", "blur_y", 1))
        graph.add_pass(f"energy_wave.composite.{view.name}", composite_setup, composite_execute)

    def release(self) -> None:
        for obj in (self._records, self._vao, *self._fullscreen.values()):
            if obj is not None:
                obj.release()
        self._records = self._vao = None
        self._fullscreen.clear()
