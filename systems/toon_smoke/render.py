"""Render passes of the toon_smoke plugin (seeds/002 §3.5 and its "future work" outlines).

Per view, two passes go into the render graph:

* ``toon_smoke.surface.<view>`` (opaque): draws each volume's isosurface mesh with the colour of a 1D toon-ramp
  texture (nearest filtering: hard bands) at c = (−v·g + 1)/2, and its sphere obstacle in two cel bands.  It writes
  the view's colour and depth and creates the transient ``toon_smoke.edges.<view>`` (object id, linear depth).
* ``toon_smoke.outline.<view>``: reads the edge buffer and paints the silhouette and inner contour lines over the
  view's colour.

The meshes are uploaded only when the simulation re-meshed (``mesh_version``).  Any number of volumes is drawn; the
outline pass keeps their parameters in uniform arrays and runs in batches of 64 volumes.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import moderngl
import numpy as np

from components.toon_smoke import ToonSmokeState, ToonSmokeVolumeConfig
from engine.render.feature import OPAQUE, RenderFeature, View
from engine.render.graph import TextureDesc
from engine.render.passes import current_vao, display_to_hdr, primitive, set_uniforms
from engine.spatial import Transform

SHADERS = Path(__file__).parent / "shaders"
RAMP_TEXELS = 256
OUTLINE_BATCH = 64  # volumes per outline pass (the shader's uniform arrays); any number are drawn


def _outline_reach(data: list[VolumeDraw]) -> int:
    return int(np.ceil(max((d.outline_width for d in data), default=0.0)))


def screen_rect(view: View, data: list[VolumeDraw], pad: int = 0) -> tuple[int, int, int, int] | None:
    """Pixel rectangle (x, y, w, h) of the view covering every volume's box (projected corners, ``pad`` pixels
    more on each side), or None when no volume is in front of the camera and on screen.  A box that reaches
    behind the camera makes it the whole view (its projection is unbounded).  Perspective views; orthographic
    ones have w = 1 everywhere, so the same code holds."""
    if not data:
        return None
    if any(d.bounds is None for d in data):
        return (0, 0, view.width, view.height)
    bits = np.array([[(i >> k) & 1 for k in range(3)] for i in range(8)], bool)
    corners = []
    for draw in data:
        lo, hi = draw.bounds
        local = np.where(bits, hi, lo)
        corners.append(local @ draw.model[:3, :3].T.astype(np.float64) + draw.model[:3, 3])
    clip = np.stack([np.c_[c, np.ones(8)] @ view.view_proj.T.astype(np.float64) for c in corners])  # (n, 8, 4)
    in_front = np.any(clip[..., 3] > 1e-6, axis=1)
    if not in_front.any():
        return None
    clip = clip[in_front].reshape(-1, 4)  # volumes wholly behind the camera are not seen
    w = clip[:, 3]
    if np.any(w <= 1e-6):
        return (0, 0, view.width, view.height)
    ndc = clip[:, :3] / w[:, None]
    if np.all(ndc[:, 0] < -1) or np.all(ndc[:, 0] > 1) or np.all(ndc[:, 1] < -1) or np.all(ndc[:, 1] > 1) \
            or np.all(ndc[:, 2] > 1):
        return None
    x0 = int(np.floor((ndc[:, 0].min() + 1) * 0.5 * view.width)) - pad
    x1 = int(np.ceil((ndc[:, 0].max() + 1) * 0.5 * view.width)) + pad
    y0 = int(np.floor((ndc[:, 1].min() + 1) * 0.5 * view.height)) - pad
    y1 = int(np.ceil((ndc[:, 1].max() + 1) * 0.5 * view.height)) + pad
    x0, y0 = max(x0, 0), max(y0, 0)
    x1, y1 = min(x1, view.width), min(y1, view.height)
    if x1 <= x0 or y1 <= y0:
        return None
    return (x0, y0, x1 - x0, y1 - y0)


def ramp_texels(colors, positions, texels: int = RAMP_TEXELS) -> np.ndarray:
    """The 1D tone-mapping texture of figure 3: texel i (c = (i + ½)/texels) takes the colour of the last band
    whose start position is ≤ c.  Returns (texels, 3) float32."""
    c = (np.arange(texels) + 0.5) / texels
    band = np.searchsorted(np.asarray(positions, float), c, side="right") - 1
    return np.asarray(colors, np.float32)[np.clip(band, 0, len(colors) - 1)]


@dataclass
class VolumeDraw:
    """What the passes need of one volume, copied in render-extract."""

    entity: int
    index: int
    mesh_version: int
    mesh: tuple[np.ndarray, np.ndarray] | None  # (interleaved vertices, indices) when it changed, else None
    model: np.ndarray  # 4x4 float32, rigid (scale ignored like the simulation)
    ramp: tuple
    outline_width: float
    outline_color: tuple
    outline_threshold: float
    obstacle: tuple | None  # (centre, radius, colour)
    bounds: tuple[np.ndarray, np.ndarray] | None = None  # local box holding the mesh and the obstacle


@dataclass
class _GpuMesh:
    vbo: moderngl.Buffer
    ibo: moderngl.Buffer
    vao: moderngl.VertexArray
    count: int
    version: int

    def release(self) -> None:
        self.vao.release()
        self.vbo.release()
        self.ibo.release()


def rigid_matrix(t: Transform) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = t.rotation_matrix()
    m[:3, 3] = t.position
    return m


class ToonSmokeFeature(RenderFeature):
    name = "toon_smoke"
    phase = OPAQUE

    def __init__(self, renderer) -> None:
        super().__init__(renderer)
        self._meshes: dict[int, _GpuMesh] = {}
        self._ramps: dict[tuple, moderngl.Texture] = {}
        self._sphere: moderngl.VertexArray | None = None
        self._sphere_buffers: tuple = ()
        self._outline_vao: moderngl.VertexArray | None = None

    # ------------------------------------------------------------------ extract
    def extract(self, world) -> list[VolumeDraw]:
        out = []
        query = world.query(Transform, ToonSmokeVolumeConfig, ToonSmokeState)
        alive = {entity for entity, _ in query}
        for entity in [e for e in self._meshes if e not in alive]:  # despawned volumes
            self._meshes.pop(entity).release()
        for index, (entity, (t, cfg, state)) in enumerate(query):
            gpu = self._meshes.get(entity)
            mesh = None
            if (gpu is None or gpu.version != state.mesh_version) and state.mesh_vertices is not None:
                verts = np.concatenate([state.mesh_vertices, state.mesh_normals], axis=1).astype(np.float32)
                mesh = (verts, state.mesh_faces.astype(np.uint32).ravel())
            obstacle = None
            half = 0.5 * np.asarray(cfg.extent, np.float64)
            lo, hi = -half, half.copy()
            if cfg.obstacle_radius > 0.0:
                obstacle = (tuple(cfg.obstacle_center), cfg.obstacle_radius, tuple(cfg.obstacle_color))
                centre = np.asarray(cfg.obstacle_center, np.float64)
                lo, hi = np.minimum(lo, centre - cfg.obstacle_radius), np.maximum(hi, centre + cfg.obstacle_radius)
            out.append(VolumeDraw(entity, index, state.mesh_version, mesh, rigid_matrix(t).astype(np.float32),
                                  (tuple(map(tuple, cfg.ramp_colors)), tuple(cfg.ramp_positions)),
                                  cfg.outline_width, tuple(cfg.outline_color), cfg.outline_depth_threshold,
                                  obstacle, (lo, hi)))
        exposure = float(self.renderer.settings.exposure)
        used = {(draw.ramp, exposure) for draw in out}
        for key in [k for k in self._ramps if k not in used]:  # a ramp or exposure edited away, volumes gone
            self._ramps.pop(key).release()
        return out

    # ---------------------------------------------------------------- resources
    def _program(self) -> moderngl.Program:
        return self.renderer.load_program(SHADERS, "toon")

    def _upload(self, draw: VolumeDraw) -> _GpuMesh | None:
        gpu = self._meshes.get(draw.entity)
        if gpu is not None:  # remade when F5 reloaded the shader
            gpu.vao = current_vao(gpu.vao, self._program(), lambda p: self.ctx.vertex_array(
                p, [(gpu.vbo, "3f 3f", "in_position", "in_normal")], gpu.ibo))
        if draw.mesh is None or (gpu is not None and gpu.version == draw.mesh_version):
            return gpu  # unchanged, or already uploaded for an earlier view this frame
        verts, indices = draw.mesh
        vdata, idata = verts.tobytes() or b"\0" * 24, indices.tobytes() or b"\0" * 12
        if gpu is None or gpu.vbo.size < len(vdata) or gpu.ibo.size < len(idata):
            if gpu is not None:
                gpu.release()
            vbo = self.ctx.buffer(reserve=max(len(vdata) * 3 // 2, 1024))
            ibo = self.ctx.buffer(reserve=max(len(idata) * 3 // 2, 1024))
            vao = self.ctx.vertex_array(self._program(), [(vbo, "3f 3f", "in_position", "in_normal")], ibo)
            gpu = _GpuMesh(vbo, ibo, vao, 0, -1)
            self._meshes[draw.entity] = gpu
        gpu.vbo.write(vdata)
        gpu.ibo.write(idata)
        gpu.count, gpu.version = len(indices), draw.mesh_version
        return gpu

    def _ramp(self, key: tuple) -> moderngl.Texture:
        """The ramp's texels as the HDR colours that reach the screen as the configured ones (the tone map
        inverted once per colour here, not per fragment)."""
        exposure = float(self.renderer.settings.exposure)
        tex = self._ramps.get((key, exposure))
        if tex is None:
            texels = display_to_hdr(ramp_texels(*key), exposure)
            tex = self.ctx.texture((RAMP_TEXELS, 1), 3, texels.tobytes(), dtype="f4")
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            tex.repeat_x = tex.repeat_y = False
            self._ramps[(key, exposure)] = tex
        return tex

    def _sphere_vao(self) -> moderngl.VertexArray:
        if self._sphere is None:
            verts, idx = primitive("sphere")
            self._sphere_buffers = (self.ctx.buffer(verts.tobytes()), self.ctx.buffer(idx.tobytes()))
        vbo, ibo = self._sphere_buffers
        self._sphere = current_vao(self._sphere, self._program(), lambda p: self.ctx.vertex_array(
            p, [(vbo, "3f 3f", "in_position", "in_normal")], ibo))  # new, or F5 reloaded the shader
        return self._sphere

    # ------------------------------------------------------------------- passes
    def add_passes(self, graph, view: View, data: list[VolumeDraw]) -> None:
        if not data:
            return
        # outline widths are in window pixels: as many of the view's at its render scale, and at least one
        data = [replace(d, outline_width=max(view.view_pixels(d.outline_width), 1.0) if d.outline_width > 0.0
                        else 0.0) for d in data]
        handles = {}

        def setup(b):
            view.color = b.write(view.color)
            view.depth = b.write(view.depth)
            edges = b.create(f"toon_smoke.edges.{view.name}", TextureDesc(view.width, view.height, "rg32f"))
            handles["edges"] = b.write(edges)

        graph.add_pass(f"toon_smoke.surface.{view.name}", setup,
                       lambda pc: self._draw_surfaces(pc, view, data, handles["edges"]))
        if any(d.outline_width > 0.0 for d in data):
            def outline_setup(b):
                b.read(handles["edges"])
                view.color = b.write(view.color)

            graph.add_pass(f"toon_smoke.outline.{view.name}", outline_setup,
                           lambda pc: self._draw_outline(pc, view, data, handles["edges"]))

    def _view_uniforms(self, view: View) -> dict:
        return dict(view_proj=view.view_proj.T.copy(), camera_pos=tuple(float(x) for x in view.camera_pos),
                    camera_forward=tuple(float(x) for x in view.camera_forward), ortho=bool(view.ortho),
                    sun_dir=tuple(float(x) for x in self.renderer.sun_direction))

    def _draw_surfaces(self, pc, view: View, data: list[VolumeDraw], edges_handle) -> None:
        edges = pc.get(edges_handle)
        rect = screen_rect(view, data, pad=_outline_reach(data) + 1)
        if rect is None:  # every volume is off screen
            return
        # the whole target: a full clear is queued like a draw, while a scissored one is done by the CPU on
        # llvmpipe once the texture's earlier users are drawn (the main thread waited 5 ms a frame in the demo)
        self.renderer.framebuffer(edges).clear(0.0, 0.0, 0.0, 0.0)
        fbo = self.renderer.framebuffer([pc.get(view.color), edges], pc.get(view.depth))
        fbo.use()
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
        prog = self._program()
        set_uniforms(prog, **self._view_uniforms(view))
        for draw in data:
            gpu = self._upload(draw)
            if gpu is not None and gpu.count:
                self._ramp(draw.ramp).use(0)
                set_uniforms(prog, model=draw.model.T.copy(), mode=0, ramp=0, object_id=float(2 * draw.index + 1))
                gpu.vao.render(moderngl.TRIANGLES, vertices=gpu.count)
            if draw.obstacle is not None:
                centre, radius, colour = draw.obstacle
                local = np.eye(4)
                local[:3, :3] *= 2.0 * radius  # the primitive is a unit-diameter sphere
                local[:3, 3] = centre
                model = (draw.model.astype(np.float64) @ local).astype(np.float32)
                lit, shade = display_to_hdr([colour, 0.6 * np.asarray(colour)], self.renderer.settings.exposure)
                set_uniforms(prog, model=model.T.copy(), mode=1, lit_color=tuple(map(float, lit)),
                             shade_color=tuple(map(float, shade)), object_id=float(2 * draw.index + 2))
                self._sphere_vao().render(moderngl.TRIANGLES)

    def _draw_outline(self, pc, view: View, data: list[VolumeDraw], edges_handle) -> None:
        rect = screen_rect(view, data)  # the outline lies on the volumes' pixels: their rectangle is enough
        if rect is None:
            return
        fbo = self.renderer.framebuffer(pc.get(view.color))
        fbo.use()
        fbo.viewport = rect  # the full-screen triangle covers the rectangle; gl_FragCoord stays in view pixels
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        prog = self.renderer.load_program(SHADERS, "outline")
        if self._outline_vao is None or self._outline_vao.program is not prog:  # new, or F5 reloaded the shader
            if self._outline_vao is not None:
                self._outline_vao.release()
            self._outline_vao = self.ctx.vertex_array(prog, [])
        pc.get(edges_handle).use(0)
        prog["edges"].value = 0
        size = -(-(max(draw.index for draw in data) + 1) // OUTLINE_BATCH) * OUTLINE_BATCH
        widths, thresholds, colors = np.zeros(size), np.zeros(size), np.zeros((size, 3))
        for draw in data:
            widths[draw.index] = draw.outline_width
            thresholds[draw.index] = draw.outline_threshold
            colors[draw.index] = draw.outline_color
        colors = display_to_hdr(colors, self.renderer.settings.exposure)
        for first in range(0, size, OUTLINE_BATCH):  # one pass per 64 volumes (one in practice)
            batch = slice(first, first + OUTLINE_BATCH)
            if not widths[batch].any():
                continue
            prog["first"].value = first
            prog["widths"].value = widths[batch].tolist()
            prog["thresholds"].value = thresholds[batch].tolist()
            prog["colors"].value = [tuple(map(float, c)) for c in colors[batch]]
            self._outline_vao.render(moderngl.TRIANGLES, vertices=3)
        fbo.viewport = (0, 0, view.width, view.height)

    def release(self) -> None:
        for mesh in self._meshes.values():
            mesh.release()
        self._meshes.clear()
        for tex in self._ramps.values():
            tex.release()
        self._ramps.clear()
        if self._sphere is not None:
            self._sphere.release()
            for buf in self._sphere_buffers:
                buf.release()
            self._sphere = None
        if self._outline_vao is not None:
            self._outline_vao.release()
            self._outline_vao = None

