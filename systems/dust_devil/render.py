"""Dust devil rendering: particle-based volume rendering (PBVR, 2.3 of seeds/004) and the field markers (4).

PBVR per view and dust devil, as passes of the render graph:

1. ``dust_devil.{e}.pbvr_clear.{view}`` creates and clears the float accumulation target (rgba16f: repeat
   counts are exact up to 2048) and a slab depth buffer;
2. ``dust_devil.{e}.pbvr_accumulate.{view}``: R draws, r = 0..R-1, into the same target (one pass, so a
   software rasteriser bins them together instead of flushing between repeats): K random pseudo-particles
   around every real particle, drawn as opaque points with a depth test, *added* into the accumulation
   target: rgb += colour, a += 1 once per covered pixel (see shaders/pbvr.vert for how the depth test makes
   that "once per repeat");
3. ``dust_devil.{e}.pbvr_resolve.{view}`` divides by R and composites over the view:
   colour = sum / R + scene · (1 − coverage / R) — the average of the R ensemble images.

R is ``repeats``, or ``drag_repeats`` while the field is being dragged.  With PBVR off the real particles are
drawn as opaque points instead.  The markers (red spheres at the box's 8 corners and centre) are lit instanced
spheres drawn with the engine's mesh shader.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import moderngl
import numpy as np

from components.dust_devil import DustDevilConfig, DustDevilState
from engine.render.feature import OPAQUE, TRANSPARENT, RenderFeature, View
from engine.render.graph import TextureDesc
from engine.render.passes import SHADERS as ENGINE_SHADERS
from engine.render.passes import lighting_uniforms, opaque_setup, primitive, set_uniforms
from engine.spatial import Transform
from systems.dust_devil.simulate import marker_points, world_positions

SHADERS = Path(__file__).parent / "shaders"
MARKER_COLOR = (0.9, 0.06, 0.04)


@dataclass
class DevilFrame:
    """What one dust devil draws this frame (copied out of the world in render-extract)."""

    entity: int
    positions: np.ndarray  # (N, 3) float32, world space
    color: tuple[float, float, float]
    pbvr: bool
    sub_particles: int  # K
    repeats: int  # R this frame (drag_repeats while dragging)
    radius: float
    point_size: float
    dragging: bool


def extract_devils(world) -> list[DevilFrame]:
    out = []
    for entity, (t, cfg, state) in world.query(Transform, DustDevilConfig, DustDevilState):
        if not state.started:
            continue
        dragging = state.dragging(world.tick)
        out.append(DevilFrame(entity, world_positions(state, t).astype(np.float32), tuple(cfg.color), cfg.pbvr,
                              cfg.sub_particles, cfg.drag_repeats if dragging else cfg.repeats,
                              cfg.sub_particle_radius, cfg.point_size, dragging))
    return out


def slab_depth(r: int, repeats: int) -> float:
    """NDC depth of repeat r's slab: strictly decreasing in r, so each repeat passes GL_LESS once per pixel."""
    return 1.0 - 2.0 * (r + 1) / (repeats + 1)


class DustDevilParticles(RenderFeature):
    """PBVR (or plain points) for every dust devil."""

    name = "dust_devil"
    phase = TRANSPARENT

    def __init__(self, renderer) -> None:
        super().__init__(renderer)
        self._buffers: dict[int, tuple[moderngl.Buffer, dict[str, moderngl.VertexArray]]] = {}
        self._uploaded: dict[int, int] = {}  # entity -> frame index of the last upload
        self.declared_repeats: dict[tuple[int, str], int] = {}  # (entity, view) -> R of the last declared frame

    def extract(self, world) -> list[DevilFrame]:
        return extract_devils(world)

    # -------------------------------------------------------------------------- GL objects
    def _vao(self, devil: DevilFrame, program: str) -> moderngl.VertexArray:
        """The VAO of ``program`` over the devil's particle buffer, uploaded once per frame."""
        nbytes = max(devil.positions.nbytes, 12)
        buf, vaos = self._buffers.get(devil.entity, (None, {}))
        if buf is None or buf.size < nbytes:
            if buf is not None:
                buf.release()
                for vao in vaos.values():
                    vao.release()
            buf, vaos = self.ctx.buffer(reserve=nbytes), {}
            self._buffers[devil.entity] = (buf, vaos)
            self._uploaded.pop(devil.entity, None)
        frame = self.renderer.frame_index
        if self._uploaded.get(devil.entity) != frame:
            buf.write(devil.positions.tobytes())
            self._uploaded[devil.entity] = frame
        if program not in vaos:
            prog = self.renderer.load_program(SHADERS, program)
            vaos[program] = self.ctx.vertex_array(prog, [(buf, "3f", "in_position")])
        return vaos[program]

    # ------------------------------------------------------------------------------ passes
    def add_passes(self, graph, view: View, data: list[DevilFrame]) -> None:
        for devil in data:
            if devil.pbvr:
                self._add_pbvr(graph, view, devil)
            else:
                self._add_points(graph, view, devil)

    def _add_points(self, graph, view: View, devil: DevilFrame) -> None:
        def execute(pc):
            fbo = self.renderer.framebuffer(pc.get(view.color), pc.get(view.depth))
            fbo.use()
            self.ctx.enable(moderngl.DEPTH_TEST | moderngl.PROGRAM_POINT_SIZE)
            self.ctx.disable(moderngl.BLEND)
            vao = self._vao(devil, "particles")
            set_uniforms(vao.program, view_proj=view.view_proj.T.copy(), point_size=devil.point_size,
                         color=devil.color)
            vao.render(moderngl.POINTS, vertices=len(devil.positions))
            self.ctx.disable(moderngl.PROGRAM_POINT_SIZE)

        graph.add_pass(f"dust_devil.{devil.entity}.points.{view.name}", opaque_setup(view), execute)

    def _add_pbvr(self, graph, view: View, devil: DevilFrame) -> None:
        prefix = f"dust_devil.{devil.entity}"
        h: dict[str, Any] = {}

        def clear_setup(b):
            h["acc"] = b.write(b.create(f"{prefix}.accumulation.{view.name}",
                                        TextureDesc(view.width, view.height, "rgba16f")))
            h["slab"] = b.write(b.create(f"{prefix}.slab_depth.{view.name}",
                                         TextureDesc(view.width, view.height, "depth24")))

        def clear(pc):
            fbo = self.renderer.framebuffer(pc.get(h["acc"]), pc.get(h["slab"]))
            fbo.use()
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)

        graph.add_pass(f"{prefix}.pbvr_clear.{view.name}", clear_setup, clear)
        self.declared_repeats[(devil.entity, view.name)] = devil.repeats
        graph.add_pass(f"{prefix}.pbvr_accumulate.{view.name}", self._repeat_setup(view, h),
                       self._repeat_execute(view, devil, h))

        def resolve_setup(b):
            b.read(h["acc"])
            view.color = b.write(view.color)

        graph.add_pass(f"{prefix}.pbvr_resolve.{view.name}", resolve_setup, self._resolve_execute(view, devil, h))

    @staticmethod
    def _repeat_setup(view: View, h: dict):
        def setup(b):
            b.read(view.depth)
            h["acc"] = b.write(h["acc"])
            h["slab"] = b.write(h["slab"])

        return setup

    def _repeat_execute(self, view: View, devil: DevilFrame, h: dict):
        def execute(pc):
            fbo = self.renderer.framebuffer(pc.get(h["acc"]), pc.get(h["slab"]))
            fbo.use()
            ctx = self.ctx
            ctx.enable(moderngl.DEPTH_TEST | moderngl.BLEND | moderngl.PROGRAM_POINT_SIZE)
            ctx.depth_func = "<"
            ctx.blend_func = moderngl.ONE, moderngl.ONE
            scene_depth = pc.get(view.depth)
            compare = scene_depth.compare_func
            scene_depth.compare_func = ""  # read raw depth values
            scene_depth.use(0)
            vao = self._vao(devil, "pbvr")
            for r in range(devil.repeats):
                set_uniforms(vao.program, view_proj=view.view_proj.T.copy(), sub_particles=devil.sub_particles,
                             repeat_index=r, frame_seed=int(self.renderer.frame_index % 2**31), radius=devil.radius,
                             slab_depth=slab_depth(r, devil.repeats), point_size=devil.point_size,
                             color=devil.color, scene_depth=0)
                vao.render(moderngl.POINTS, vertices=len(devil.positions), instances=devil.sub_particles)
            scene_depth.compare_func = compare
            ctx.disable(moderngl.BLEND | moderngl.PROGRAM_POINT_SIZE)

        return execute

    def _resolve_execute(self, view: View, devil: DevilFrame, h: dict):
        def execute(pc):
            fbo = self.renderer.framebuffer(pc.get(view.color))
            fbo.use()
            ctx = self.ctx
            ctx.disable(moderngl.DEPTH_TEST)
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA
            vao = self._resolve_vao()
            pc.get(h["acc"]).use(0)
            set_uniforms(vao.program, accumulation=0, inv_repeats=1.0 / devil.repeats)
            vao.render(moderngl.TRIANGLES, vertices=3)
            ctx.disable(moderngl.BLEND)

        return execute

    def _resolve_vao(self) -> moderngl.VertexArray:
        vao = getattr(self, "_resolve", None)
        if vao is None:
            prog = self.renderer.program((ENGINE_SHADERS / "fullscreen.vert").read_text(),
                                         (SHADERS / "resolve.frag").read_text())
            vao = self._resolve = self.ctx.vertex_array(prog, [])
        return vao

    def release(self) -> None:
        for buf, vaos in self._buffers.values():
            for vao in vaos.values():
                vao.release()
            buf.release()
        self._buffers.clear()
        if getattr(self, "_resolve", None) is not None:
            self._resolve.release()
            self._resolve = None


class DustDevilMarkers(RenderFeature):
    """The field box's corner and centre points as red spheres (section 4), so the user sees what they drag."""

    name = "dust_devil_markers"
    phase = OPAQUE
    INSTANCE_FLOATS = 20

    def __init__(self, renderer) -> None:
        super().__init__(renderer)
        self._gl: tuple | None = None

    def extract(self, world) -> np.ndarray:
        rows = []
        for _, (t, cfg) in world.query(Transform, DustDevilConfig):
            if not cfg.show_markers:
                continue
            points = marker_points(cfg, t)
            inst = np.zeros((len(points), self.INSTANCE_FLOATS), np.float32)
            d = 2.0 * cfg.marker_radius  # the engine's sphere has diameter 1
            inst[:, 0], inst[:, 5], inst[:, 10], inst[:, 15] = d, d, d, 1.0  # column-major model matrix
            inst[:, 12:15] = points
            inst[:, 16:19] = MARKER_COLOR
            inst[:, 19] = 0.6  # a little self-illumination: visible in the shade
            rows.append(inst)
        return np.concatenate(rows) if rows else np.zeros((0, self.INSTANCE_FLOATS), np.float32)

    def _vao(self, count: int) -> tuple[moderngl.VertexArray, moderngl.Buffer]:
        needed = max(count, 9) * self.INSTANCE_FLOATS * 4
        if self._gl is None or self._gl[1].size < needed:
            self.release()
            verts, idx = primitive("sphere")
            inst = self.ctx.buffer(reserve=needed)
            vbo, ibo = self.ctx.buffer(verts.tobytes()), self.ctx.buffer(idx.tobytes())
            prog = self.renderer.load_program(ENGINE_SHADERS, "mesh")
            vao = self.ctx.vertex_array(prog, [(vbo, "3f 3f", "in_position", "in_normal"),
                                               (inst, "4f 4f 4f 4f 4f/i", "m0", "m1", "m2", "m3", "in_color")], ibo)
            self._gl = (vao, inst, vbo, ibo)
        return self._gl[0], self._gl[1]

    def add_passes(self, graph, view: View, data: np.ndarray) -> None:
        if not len(data):
            return

        def execute(pc):
            fbo = self.renderer.framebuffer(pc.get(view.color), pc.get(view.depth))
            fbo.use()
            self.ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
            self.ctx.disable(moderngl.BLEND)
            vao, inst = self._vao(len(data))
            inst.write(data.tobytes())
            set_uniforms(vao.program, **lighting_uniforms(self.renderer, view))
            vao.render(moderngl.TRIANGLES, instances=len(data))
            self.ctx.disable(moderngl.CULL_FACE)

        graph.add_pass(f"dust_devil_markers.{view.name}", opaque_setup(view), execute)

    def release(self) -> None:
        if self._gl is not None:
            for obj in self._gl:
                obj.release()
            self._gl = None
