"""The water's render feature: the re-triangulated surface (transparent phase, after the opaque meshes, so the
bodies floating in it show through) and the wireframe debug view of fig. 3.2.

Extract copies the mesh out of the simulation state (positions and normals as float32, triangles as uint32);
the pass draws it depth-tested against the opaque scene without writing depth, blended premultiplied.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import moderngl
import numpy as np

from components.water_surface import WaterState, WaterSurface
from engine.render.feature import TRANSPARENT, RenderFeature, View
from engine.render.passes import current_vao, lighting_uniforms, set_uniforms
from engine.render.terrain_shadow import receiver as terrain_receiver
from engine.spatial import Transform
from systems.water_surface.kernels import vertex_records
from systems.water_surface.mesh import retriangulate, wire_arrays
from systems.water_surface.simulate import water_grid

SHADERS = Path(__file__).parent / "shaders"


class _Buffers:
    """Growable vertex / index buffers and their vertex array for one water surface."""

    def __init__(self) -> None:
        self.vbo = self.ibo = self.vao = None
        self.wire_vbo = self.wire_vao = None

    def release(self) -> None:
        for obj in (self.vao, self.vbo, self.ibo, self.wire_vao, self.wire_vbo):
            if obj is not None:
                obj.release()
        self.vbo = self.ibo = self.vao = self.wire_vbo = self.wire_vao = None


class WaterFeature(RenderFeature):
    name = "water_surface"
    phase = TRANSPARENT

    def __init__(self, renderer) -> None:
        super().__init__(renderer)
        self._buffers: dict[int, _Buffers] = {}
        self._meshes: dict[int, Any] = {}  # each surface's last mesh, reused while its outline keeps its shape

    def extract(self, world) -> list[dict[str, Any]]:
        out = []
        meshes, self._meshes = self._meshes, {}
        for entity, (t, cfg, state) in world.query(Transform, WaterSurface, WaterState):
            grid = water_grid(cfg, state, t)
            nz, nx = state.heights.shape
            mesh = retriangulate(nx, nz, state.point_uv, state.point_kind, state.segments, meshes.get(entity))
            self._meshes[entity] = mesh
            # mesh.vertex_arrays packed as float32 rows in one compiled pass (the same bits; 0.05 ms instead of
            # 0.73 ms a frame for the demo's 64 x 64 pond, on the main thread)
            vertices = vertex_records(state.heights, grid.h, grid.x0, grid.z0, grid.y0, state.point_uv,
                                      state.point_heights)
            item = dict(entity=entity,
                        vertices=vertices,
                        indices=mesh.triangles.astype(np.uint32).ravel(),
                        shallow=tuple(cfg.shallow_color), deep=tuple(cfg.deep_color), clarity=cfg.clarity,
                        floor=grid.y0 - cfg.depth, rest=grid.y0, wire=None)
            if cfg.wireframe:
                item["wire"] = wire_arrays(vertices[:, :3], mesh).astype(np.float32)
            out.append(item)
        for entity in [e for e in self._buffers if e not in self._meshes]:  # despawned surfaces
            self._buffers.pop(entity).release()
        return out

    def _upload(self, item: dict[str, Any]) -> _Buffers:
        """The item's buffers, written once per frame however many views draw it."""
        buf = self._buffers.setdefault(item["entity"], _Buffers())
        if item.get("uploaded"):
            return buf
        item["uploaded"] = True
        verts, idx = item["vertices"], item["indices"]
        if buf.vbo is None or buf.vbo.size < verts.nbytes or buf.ibo.size < idx.nbytes:
            buf.release()
            buf.vbo = self.ctx.buffer(reserve=max(verts.nbytes * 2, 1024))
            buf.ibo = self.ctx.buffer(reserve=max(idx.nbytes * 2, 1024))
        buf.vbo.write(verts.tobytes())
        buf.ibo.write(idx.tobytes())
        wire = item["wire"]
        if wire is not None:
            prog = self.renderer.load_program(SHADERS, "wire")
            if buf.wire_vbo is None or buf.wire_vbo.size < wire.nbytes or buf.wire_vao.program is not prog:
                if buf.wire_vao is not None:  # grown, or F5 reloaded the shader
                    buf.wire_vao.release()
                    buf.wire_vbo.release()
                buf.wire_vbo = self.ctx.buffer(reserve=max(wire.nbytes * 2, 1024))
                buf.wire_vao = self.ctx.vertex_array(prog, [(buf.wire_vbo, "3f 3f", "in_position", "in_color")])
            buf.wire_vbo.write(wire.tobytes())
        return buf

    def add_passes(self, graph, view: View, data) -> None:
        if not data:
            return

        def setup(b):
            view.color = b.write(view.color)
            b.read(view.depth)

        def execute(pc):
            fbo = self.renderer.framebuffer(pc.get(view.color), pc.get(view.depth))
            fbo.use()
            fbo.depth_mask = False
            self.ctx.enable(moderngl.DEPTH_TEST | moderngl.BLEND)
            self.ctx.disable(moderngl.CULL_FACE)
            self.ctx.blend_func = moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA
            # the hills' shadow (engine/render/terrain_shadow.py)
            terrain_defines, terrain_uniforms = terrain_receiver(self.renderer.terrain_shadow_in(view), self.ctx)
            water = self.renderer.load_program(SHADERS, "water", terrain_defines)
            lights = lighting_uniforms(self.renderer, view)
            set_uniforms(water, **lights, **terrain_uniforms)
            for item in data:
                buf = self._upload(item)
                buf.vao = current_vao(buf.vao, water, lambda p: self.ctx.vertex_array(  # another variant, F5
                    p, [(buf.vbo, "3f 3f", "in_position", "in_normal")], buf.ibo, 4))
                set_uniforms(water, shallow_color=item["shallow"], deep_color=item["deep"], clarity=item["clarity"],
                             floor_y=item["floor"], rest_y=item["rest"])
                buf.vao.render(moderngl.TRIANGLES, vertices=len(item["indices"]))
            self.ctx.disable(moderngl.BLEND)
            wire = self.renderer.load_program(SHADERS, "wire")
            set_uniforms(wire, view_proj=lights["view_proj"])
            for item in data:
                if item["wire"] is not None:
                    self._buffers[item["entity"]].wire_vao.render(moderngl.LINES, vertices=len(item["wire"]))
            fbo.depth_mask = True

        graph.add_pass(f"water_surface.{view.name}", setup, execute)

    def release(self) -> None:
        for buf in self._buffers.values():
            buf.release()
        self._buffers.clear()
        self._meshes.clear()
