"""The engine's own render features: sky, terrain, lit meshes, tone mapping, composition, HUD text.

Meshes are drawn instanced, one draw call per primitive shape; the terrain mesh is uploaded once per
height field and drawn chunk by chunk at a level of detail per view (engine/render/terrain.py).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import lru_cache
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import moderngl
import numpy as np

from engine.builtin import Terrain
from engine.render.components import Hud, MeshConfig
from engine.render.feature import OPAQUE, OVERLAY, SKY, ColorLayer, RenderFeature, View, write_view_color
from engine.render.shadows import ShadowCasters, may_be_shadowed, read_shadow, receiver_uniforms
from engine.render.terrain import TerrainChunks, build_terrain_chunks, draw_ranges, select_levels, shade_texels
from engine.render.terrain_shadow import TerrainShadow
from engine.render.terrain_shadow import receiver as terrain_receiver
from engine.spatial import Transform, cross, model_matrices

if TYPE_CHECKING:
    from engine.render.renderer import Renderer

SHADERS = __import__("pathlib").Path(__file__).parent / "shaders"


def builtin_features():
    return [SkyFeature, TerrainFeature, MeshFeature, HudFeature]


def current_vao(vao: moderngl.VertexArray | None, prog: moderngl.Program,
                make: Callable[[moderngl.Program], moderngl.VertexArray]) -> moderngl.VertexArray:
    """``vao`` when it was made on ``prog``, else ``make(prog)`` with the old one released.  Features keep their
    vertex arrays across frames, and after F5 (:meth:`Renderer.reload_shaders`) ``load_program`` hands out a new
    program: one made on the old program would keep drawing the old shader, and keep it alive."""
    if vao is not None and vao.program is prog:
        return vao
    if vao is not None:
        vao.release()
    return make(prog)


def set_uniforms(prog: moderngl.Program | moderngl.ComputeShader, **values: Any) -> None:
    """Set the uniforms that the program really uses (the compiler drops unused ones).  One dictionary look-up
    a name: ``name in prog`` walks the program's members (~0.1 ms a call for the lit mesh shader's uniforms)."""
    for name, value in values.items():
        member = prog.get(name, None)
        if member is None:
            continue
        if isinstance(value, np.ndarray):
            member.write(value.astype(np.float32).tobytes() if value.dtype != np.int32 else value.tobytes())
        else:
            member.value = value


def display_to_hdr(display: Any, exposure: float) -> np.ndarray:
    """The HDR colour that the tone map (``display_color.glsl``) turns into ``display`` (sRGB-ish 0..1): the CPU
    twin of the shader's ``display_to_hdr``, for colours that are constant over a draw (cel bands, outlines),
    so their fragments need not invert the tone map per pixel.  Returns float32 of ``display``'s shape."""
    d = np.clip(np.asarray(display, np.float64), 0.0, 1.0)
    y = np.clip(d ** 2.2, 0.0, 0.99)
    a, b, c = 2.51 - 2.43 * y, 0.03 - 0.59 * y, -0.14 * y
    x = (-b + np.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)
    return (x / max(float(exposure), 1e-4)).astype(np.float32)


def lighting_uniforms(renderer: Renderer, view: View) -> dict[str, Any]:
    s = renderer.settings
    return dict(view_proj=view.view_proj.T.copy(), sun_dir=tuple(renderer.sun_direction),
                sun_color=tuple(renderer.sun_color), ambient=renderer.ambient, sky_top=tuple(s.sky_top),
                sky_horizon=tuple(s.sky_horizon), camera_pos=tuple(view.camera_pos),
                fog_density=0.0 if view.ortho else s.fog_density)  # no aerial haze in map-like top views


def opaque_setup(view: View):
    """Setup callback of an opaque pass: writes the view's colour and depth."""

    def setup(b):
        view.color = b.write(view.color)
        view.depth = b.write(view.depth)

    return setup


# ---------------------------------------------------------------------------- sky
class SkyFeature(RenderFeature):
    """Sky gradient and sun, drawn after the opaque passes only where the depth is still at the far plane.

    The gradient and the sun's halo cover the empty pixels; the disc (``pow(cos, 900)``) is drawn apart, over a
    rectangle bounding the cone where it adds anything, instead of a branch every sky pixel pays for on a
    software rasteriser.
    """

    name = "sky"
    phase = SKY
    fills_background = True  # depth test "<=" at z = w: every pixel still at the cleared depth 1.0 is drawn
    DISC_COS = 0.98  # sun.frag: below this cosine the disc adds < 1e-6

    def __init__(self, renderer: Renderer) -> None:
        super().__init__(renderer)
        self._vaos: dict[str, moderngl.VertexArray] = {}

    def release(self) -> None:
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()

    def static_key(self, view: View, data) -> Any:
        return ()  # a function of the view and the light alone (the renderer's part of the static key)

    def add_passes(self, graph, view: View, data) -> None:
        def setup(b):
            view.color = b.write(view.color)
            b.read(view.depth)

        def execute(pc):
            sky = self._vao("sky")
            fbo = self.renderer.framebuffer(pc.get(view.color), pc.get(view.depth))
            fbo.use()
            fbo.depth_mask = False
            self.ctx.disable(moderngl.BLEND)
            self.ctx.enable(moderngl.DEPTH_TEST)
            self.ctx.depth_func = "<="
            s = self.renderer.settings
            inv = np.linalg.inv(view.view_proj.astype(np.float64))
            ray = dict(inv_view_proj=inv.astype(np.float32).T.copy(), camera_pos=tuple(view.camera_pos),
                       ortho=view.ortho, camera_forward=tuple(view.camera_forward))
            sun = dict(sun_dir=tuple(self.renderer.sun_direction), sun_color=tuple(self.renderer.sun_color))
            set_uniforms(sky.program, sky_top=tuple(s.sky_top), sky_horizon=tuple(s.sky_horizon), **ray, **sun)
            sky.render(moderngl.TRIANGLES, vertices=3)
            rect = sun_rect(view, self.renderer.sun_direction, self.DISC_COS)
            if rect is not None:
                self.ctx.enable(moderngl.BLEND)
                self.ctx.blend_func = moderngl.ONE, moderngl.ONE
                disc = self._vao("sun")
                set_uniforms(disc.program, rect=rect, **ray, **sun)
                disc.render(moderngl.TRIANGLE_STRIP, vertices=4)
                self.ctx.disable(moderngl.BLEND)
            self.ctx.depth_func = "<"
            fbo.depth_mask = True

        graph.add_pass(f"sky.{view.name}", setup, execute)

    def _vao(self, name: str) -> moderngl.VertexArray:
        """A buffer-less VAO over ``shaders/<name>``, remade when F5 reloaded the program."""
        prog = self.renderer.load_program(SHADERS, name)
        vao = self._vaos[name] = current_vao(self._vaos.get(name), prog, lambda p: self.ctx.vertex_array(p, []))
        return vao


def sun_rect(view: View, sun_dir: np.ndarray, min_cos: float) -> tuple[float, float, float, float] | None:
    """The rectangle (x0, y0, x1, y1, normalised device coordinates, clamped to the view) that holds every view
    ray within ``acos(min_cos)`` of the sun's direction, or None when no such ray reaches the view.

    The cone's rays are bounded by the square of half-size tan(angle) on the plane at unit distance along the
    sun's direction; its corners are projected as directions (w = 0: points at infinity).  Orthographic views
    share one ray (the camera's forward): the whole view, or nothing.
    """
    d = np.asarray(sun_dir, np.float64)
    d = d / np.linalg.norm(d)
    if view.ortho:
        return (-1.0, -1.0, 1.0, 1.0) if float(np.dot(view.camera_forward, d)) > min_cos else None
    half = float(np.tan(np.arccos(min_cos)))
    a = cross(d, [0.0, 1.0, 0.0] if abs(d[1]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = cross(d, a)
    corners = np.array([d + half * (sa * a + sb * b) for sa in (-1, 1) for sb in (-1, 1)])
    clip = np.concatenate([corners, np.zeros((4, 1))], axis=1) @ np.asarray(view.view_proj, np.float64).T
    front = clip[:, 3] > 1e-6
    if not front.any():  # the square, so the cone it spans, lies behind the camera
        return None
    if not front.all():  # the cone straddles the camera's plane: no finite rectangle bounds it
        return (-1.0, -1.0, 1.0, 1.0)
    ndc = clip[:, :2] / clip[:, 3:4]
    x0, y0 = np.maximum(ndc.min(axis=0), -1.0)
    x1, y1 = np.minimum(ndc.max(axis=0), 1.0)
    if x0 >= x1 or y0 >= y1:
        return None
    return float(x0), float(y0), float(x1), float(y1)


# ------------------------------------------------------------------------ terrain
@dataclass
class _TerrainMesh:
    key: tuple
    chunks: TerrainChunks
    vaos: dict  # (vertex_shade, textured, shadows) -> the vertex array of that shader variant
    vbo: moderngl.Buffer
    ibo: moderngl.Buffer
    shade: moderngl.Texture  # rgba8, one texel per grid point: sqrt(baked diffuse + ambient light × albedo / scale)
    shade_key: tuple = ()  # the light, colours, model rotation and terrain shadow it was baked with
    shade_scale: float = 1.0
    self_shadowed: bool = False  # some of its grid points are in its own shadow (the TERRAIN_SHADOW variant)
    detail: moderngl.Texture | None = None  # the ground texture (rgba8, sqrt of mix(1, colour, strength)), tiled
    detail_key: tuple = ()  # the texture array and strength it was made from

    def release(self) -> None:
        for obj in (*self.vaos.values(), self.vbo, self.ibo, self.shade, self.detail):
            if obj is not None:
                obj.release()
        self.vaos.clear()


class TerrainFeature(RenderFeature):
    """Height-field terrains, chunked with a level of detail per view (engine/render/terrain.py)."""

    name = "terrain"
    phase = OPAQUE

    def __init__(self, renderer: Renderer) -> None:
        super().__init__(renderer)
        self._meshes: dict[int, _TerrainMesh] = {}
        self.last_draws: dict[str, int] = {}  # view name -> draw calls issued last frame (tests, profiling)
        self.last_triangles: dict[str, int] = {}
        self.last_chunks: dict[str, int] = {}  # chunks drawn (not culled) last frame
        self.last_shadowed: dict[str, int] = {}  # of which drawn with the shadow look-up (receiver culling)
        self.bakes = 0  # shade textures baked (tests)
        self._shadows: dict[int, TerrainShadow] = {}  # per terrain: its shadow-height map (terrain_shadow.py)
        self.shadow_builds = 0  # shadow-height maps made (tests)
        # full-detail chunks take the baked light per vertex (Gouraud) instead of a texture fetch per pixel: on
        # llvmpipe that fetch was ≈ 1/3 of the terrain pass (off: every chunk fetches per pixel; A/B, tests)
        self.vertex_shade = True

    def extract(self, world) -> list:
        out = []
        for entity, (terrain, t) in world.query(Terrain, Transform):
            key = (Identity(terrain.field.heights), terrain.field.heights.shape, terrain.field.spacing,
                   terrain.texture is not None)
            out.append((entity, key, terrain, t.matrix().astype(np.float32)))
        drawn = {item[0] for item in out}
        for entity in [e for e in self._meshes if e not in drawn]:  # terrains gone
            self._meshes.pop(entity).release()
        self._update_shadows(out)
        return out

    def _update_shadows(self, terrains: list) -> None:
        """Each terrain's shadow-height map for the current sun (re-made when the sun, the field or its placement
        changed; none while ``[render] terrain_shadows`` is off), and the renderer's ``terrain_shadow``: the first
        terrain's (lowest entity id), which the meshes and the grass receive; None when it casts no shadow above
        the ground (a high sun over gentle hills: the receivers then skip the look-up)."""
        r = self.renderer
        enabled = r.settings.terrain_shadows
        keep = {}
        for entity, key, terrain, model in terrains if enabled else ():
            field = terrain.field
            shadow_key = (key, field.origin.tobytes(), model.tobytes(), tuple(np.round(r.sun_direction, 6)))
            shadow = self._shadows.pop(entity, None)
            if shadow is None or shadow.key != shadow_key:
                if shadow is not None:
                    shadow.release()
                shadow = TerrainShadow.build(shadow_key, field, model, r.sun_direction)
                self.shadow_builds += 1
            keep[entity] = shadow
        for shadow in self._shadows.values():  # terrains gone, or switched off
            shadow.release()
        self._shadows = keep
        first = keep[min(keep)] if keep else None
        r.terrain_shadow = first if first is not None and first.casts else None

    def static_key(self, view: View, data) -> Any:
        """The terrains drawn (height field, model matrix, colours, level-of-detail bound, ground texture): the
        level selection and the baked light follow from them, the view and the light; and the view's shadow map."""
        return (self.vertex_shade, shadow_key(view), self.renderer.settings.terrain_shadows) + tuple(
            (entity, key, model.tobytes(), terrain.config.lod_pixels, tuple(map(tuple, terrain.config.colors)),
             _detail_key(terrain))
            for entity, key, terrain, model in data)

    def _mesh(self, entity: int, key: tuple, terrain: Terrain) -> _TerrainMesh:
        mesh = self._meshes.get(entity)
        if mesh is not None and mesh.key == key:
            return mesh
        if mesh is not None:
            mesh.release()
        chunks = build_terrain_chunks(terrain.field)
        vbo, ibo = self.ctx.buffer(chunks.vertices.tobytes()), self.ctx.buffer(chunks.indices.tobytes())
        rows, cols = terrain.field.heights.shape
        shade = self.ctx.texture((cols, rows), 4)
        shade.repeat_x = shade.repeat_y = False
        mesh = _TerrainMesh(key, chunks, {}, vbo, ibo, shade)
        self._meshes[entity] = mesh
        return mesh

    def _bake(self, mesh: _TerrainMesh, entity: int, terrain: Terrain, model: np.ndarray) -> None:
        """(Re-)bake the mesh's shade texture when the light, the colours, the model's rotation or the terrain's
        own shadow changed."""
        r, s = self.renderer, self.renderer.settings
        light = (tuple(np.round(r.sun_direction, 6)), tuple(r.sun_color), r.ambient, tuple(s.sky_top),
                 tuple(s.sky_horizon))
        shadow = self._shadows.get(entity)
        key = (light, tuple(map(tuple, terrain.config.colors)), tuple(np.round(model[:3, :3], 6).ravel()),
               None if shadow is None else shadow.key)
        if key == mesh.shade_key:
            return
        sun = None if shadow is None else shadow.ground  # the sun's share on the ground (made with the map)
        texels = shade_texels(terrain.field, model, terrain.config.colors, r.sun_direction, r.sun_color, r.ambient,
                              s.sky_top, s.sky_horizon, sun)
        # 8 bits a channel (a software rasteriser filters them on its fast integer path, ~2x cheaper than half
        # floats), square-root encoded so that dark ground keeps its precision; the shader squares and scales.
        # Alpha: the sun's share past the terrain's hills, linear
        mesh.shade_scale = max(float(texels[..., :3].max()), 1e-6)
        encoded = np.sqrt(np.clip(texels / mesh.shade_scale, 0.0, 1.0))
        encoded[..., 3] = np.clip(texels[..., 3], 0.0, 1.0)
        mesh.shade.write(np.round(encoded * 255.0).astype(np.uint8).tobytes())
        mesh.self_shadowed = sun is not None and bool((sun < 1.0).any())
        mesh.shade_key = key
        self.bakes += 1

    def _upload_detail(self, mesh: _TerrainMesh, terrain: Terrain) -> None:
        """(Re-)make the mesh's ground texture when the texture or its strength changed: mix(1, colour, strength)
        per texel (linear), square-root encoded in 8 bits like the shade texture (the shader squares it), with
        mipmaps filtered bilinearly within the nearest level (a software rasteriser's cheaper path; trilinear
        would fetch twice the texels), repeating."""
        key = _detail_key(terrain)
        if key == mesh.detail_key:
            return
        if mesh.detail is not None:
            mesh.detail.release()
        strength = np.float32(terrain.config.texture_strength)
        colour = np.float32(1.0) + (terrain.texture - np.float32(1.0)) * strength
        encoded = np.round(np.sqrt(np.clip(colour, 0.0, 1.0)) * 255.0).astype(np.uint8)
        rows, cols = encoded.shape[:2]
        rgba = np.concatenate([encoded, np.full((rows, cols, 1), 255, np.uint8)], axis=-1)
        detail = self.ctx.texture((cols, rows), 4, rgba[::-1].tobytes())  # image row 0 (top) at v = 1
        detail.repeat_x = detail.repeat_y = True
        detail.build_mipmaps()
        detail.filter = (moderngl.LINEAR_MIPMAP_NEAREST, moderngl.LINEAR)
        mesh.detail, mesh.detail_key = detail, key

    def _program(self, vertex_shade: bool = False, textured: bool = False,
                 shadows: tuple[str, ...] = ()) -> moderngl.Program:
        defines = (("VERTEX_SHADE",) if vertex_shade else ()) + (("TEXTURED",) if textured else ()) + shadows
        return self.renderer.load_program(SHADERS, "terrain", defines)

    def add_passes(self, graph, view: View, data) -> None:
        if not data:
            return
        shadow = view.extra.get("shadow")

        def setup(b):
            opaque_setup(view)(b)
            read_shadow(b, view)

        def execute(pc):
            fbo = self.renderer.framebuffer(pc.get(view.color), pc.get(view.depth))
            fbo.use()
            self.ctx.enable(moderngl.DEPTH_TEST)
            self.ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
            lighting = lighting_uniforms(self.renderer, view)
            shadow_defines, shadow_uniforms = receiver_uniforms(shadow, pc)
            draws = triangles = self.last_shadowed[view.name] = self.last_chunks[view.name] = 0
            for entity, key, terrain, model in data:
                mesh = self._mesh(entity, key, terrain)
                self._bake(mesh, entity, terrain, model)
                textured = terrain.texture is not None
                detail = {}
                if textured:
                    self._upload_detail(mesh, terrain)
                    mesh.detail.use(1)
                    detail = dict(detail_map=1, detail_scale=1.0 / terrain.config.texture_size)
                levels = select_levels(mesh.chunks, model, view.view_proj, view.proj, view.camera_pos,
                                       view.height, view.ortho, terrain.config.lod_pixels)
                mesh.shade.use(0)
                # receiver culling: only the chunks a caster's shadow may reach pay for the shadow look-up
                receives = (np.zeros(len(levels), bool) if shadow is None
                            else may_be_shadowed(shadow, chunk_boxes(mesh.chunks, model)))
                self.last_chunks[view.name] += int((levels >= 0).sum())
                self.last_shadowed[view.name] += int(((levels >= 0) & receives).sum())
                for in_shadow in (False, True):
                    part = np.where(receives == in_shadow, levels, -1)
                    shadows, uniforms = (shadow_defines, shadow_uniforms) if in_shadow else ((), {})
                    if mesh.self_shadowed:
                        shadows = shadows + ("TERRAIN_SHADOW",)
                    for ranges, vertex_shade in self._batches(mesh, part):
                        prog = self._program(vertex_shade, textured, shadows)
                        set_uniforms(prog, **lighting, **detail, **uniforms, model=model.T.copy(), shade_map=0,
                                     shade_scale=mesh.shade_scale, uv_scale=mesh.chunks.uv_scale,
                                     uv_offset=mesh.chunks.uv_offset)
                        variant = (vertex_shade, textured, shadows)
                        vao = mesh.vaos[variant] = current_vao(mesh.vaos.get(variant), prog, lambda p: (
                            self.ctx.vertex_array(p, [(mesh.vbo, "3f 3f 1f", "in_position", "in_normal",
                                                       "in_skirt")], mesh.ibo, index_element_size=4)))
                        for first, count in ranges:
                            vao.render(moderngl.TRIANGLES, vertices=count, first=first)
                        draws += len(ranges)
                        triangles += sum(c for _, c in ranges) // 3
            self.last_draws[view.name], self.last_triangles[view.name] = draws, triangles

        graph.add_pass(f"terrain.{view.name}", setup, execute)

    def _batches(self, mesh: _TerrainMesh, levels: np.ndarray) -> list:
        """(draw ranges, vertex_shade) per shader variant: full-detail chunks (level 0, whose vertices are the
        baked grid points) shade per vertex when :attr:`vertex_shade` is on, the rest fetch the baked light per
        pixel."""
        if not self.vertex_shade:
            return [(draw_ranges(mesh.chunks, levels), False)]
        batches = [(draw_ranges(mesh.chunks, np.where(levels == 0, 0, -1)), True),
                   (draw_ranges(mesh.chunks, np.where(levels > 0, levels, -1)), False)]
        return [b for b in batches if b[0]]

    def release(self) -> None:
        for mesh in self._meshes.values():
            mesh.release()
        self._meshes.clear()
        for shadow in self._shadows.values():
            shadow.release()
        self._shadows.clear()
        self.renderer.terrain_shadow = None


def chunk_boxes(chunks: TerrainChunks, model: np.ndarray) -> np.ndarray:
    """(chunks, 2, 3): each chunk's bounding box in the world (the model matrix's turn of the local box)."""
    m = np.asarray(model, np.float64)
    centre = (chunks.box_min + chunks.box_max) * 0.5
    half = (chunks.box_max - chunks.box_min) * 0.5
    c = np.einsum("ij,nj->ni", m[:3, :3], centre) + m[:3, 3]
    h = np.einsum("ij,nj->ni", np.abs(m[:3, :3]), half)
    return np.stack([c - h, c + h], axis=1)


def _detail_key(terrain: Terrain) -> tuple:
    """What a terrain's ground texture is made from and how it is tiled: the decoded image (its identity: rebuilt
    with the component), the strength and the tile size; () without one."""
    if terrain.texture is None:
        return ()
    return (Identity(terrain.texture), terrain.texture.shape, terrain.config.texture_strength,
            terrain.config.texture_size)


class Identity:
    """A key part that is equal only to a key part of the same object, and keeps that object alive: ``id(obj)``
    alone may be given to a new object once the first is freed, and a cache keyed by it would show stale data."""

    __slots__ = ("obj",)

    def __init__(self, obj: Any) -> None:
        self.obj = obj

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Identity) and other.obj is self.obj

    def __hash__(self) -> int:
        return id(self.obj)

    def __repr__(self) -> str:
        return f"Identity({type(self.obj).__name__} at {id(self.obj):#x})"


# ------------------------------------------------------------------------- meshes
@lru_cache(maxsize=None)
def primitive(shape: str, segments: tuple[int, int] = (12, 20)) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (position, normal; float32) and indices (uint32) of a unit primitive; ``segments``: a sphere's
    (stacks, slices), fewer for spheres that stay small on screen (triangle setup is a software rasteriser's
    cost per triangle, however few pixels it covers)."""
    if shape == "box":
        faces = []
        for axis in range(3):
            for sign in (-1.0, 1.0):
                n = np.zeros(3)
                n[axis] = sign
                u, v = np.zeros(3), np.zeros(3)
                u[(axis + 1) % 3], v[(axis + 2) % 3] = 1.0, 1.0
                corners = [n * 0.5 + (a * u + b * v) * 0.5 for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
                faces.append([np.concatenate([c, n]) for c in corners])
        verts = np.array(faces, np.float32).reshape(-1, 6)
        base = np.arange(6)[:, None] * 4
        idx = (base + np.array([0, 1, 2, 0, 2, 3])).ravel()
        return verts, idx.astype(np.uint32)
    if shape == "sphere":
        stacks, slices = segments
        phi = np.linspace(0, np.pi, stacks + 1)[:, None]
        theta = np.linspace(0, 2 * np.pi, slices + 1)[None, :]
        n = np.stack([np.sin(phi) * np.cos(theta), np.cos(phi) * np.ones_like(theta),
                      np.sin(phi) * np.sin(theta)], axis=-1).reshape(-1, 3)
        verts = np.concatenate([n * 0.5, n], axis=1).astype(np.float32)
        r, c = np.meshgrid(np.arange(stacks), np.arange(slices), indexing="ij")
        i0 = (r * (slices + 1) + c).ravel()
        idx = np.stack([i0, i0 + 1, i0 + slices + 1, i0 + 1, i0 + slices + 2, i0 + slices + 1], -1)
        return verts, idx.astype(np.uint32).ravel()
    if shape == "plane":
        verts = np.array([[-0.5, 0, -0.5, 0, 1, 0], [0.5, 0, -0.5, 0, 1, 0], [0.5, 0, 0.5, 0, 1, 0],
                          [-0.5, 0, 0.5, 0, 1, 0]], np.float32)
        return verts, np.array([0, 2, 1, 0, 3, 2], np.uint32)
    raise ValueError(f"unknown primitive '{shape}' (box, sphere, plane)")


class MeshFeature(RenderFeature):
    """Every entity with Transform + MeshConfig, instanced: one draw call per shape.  Meshes cast sun shadows
    (those with ``cast_shadows``) and receive them."""

    name = "meshes"
    phase = OPAQUE
    INSTANCE_FLOATS = 20

    def __init__(self, renderer: Renderer) -> None:
        super().__init__(renderer)
        self._geometry: dict[str, tuple] = {}
        self._instances: dict[str, moderngl.Buffer] = {}
        # the shadow pass's own instance buffers: the lit pass rewrites its buffers later in the frame, and a
        # software rasteriser would wait for the shadow draw to finish before letting them be written
        self._shadow_instances: dict[str, moderngl.Buffer] = {}
        self._shadow_vaos: dict[str, moderngl.VertexArray] = {}

    def extract(self, world) -> dict[str, tuple[np.ndarray, int]]:
        """shape -> (instances (n, 20) float32, how many of them cast shadows: the first ones)."""
        groups: dict[str, list] = {}
        for _, (mesh, t) in world.query(MeshConfig, Transform):
            if mesh.visible:
                groups.setdefault(mesh.shape, []).append((t, mesh))
        out = {}
        for shape, items in groups.items():
            items.sort(key=lambda item: not item[1].cast_shadows)  # stable: casters first, in query order
            transforms = [t for t, _ in items]
            matrices = model_matrices(np.array([t.position for t in transforms]),
                                      np.array([t.rotation for t in transforms]),
                                      np.array([t.scale for t in transforms]))
            data = np.empty((len(items), self.INSTANCE_FLOATS), np.float32)
            data[:, :16] = matrices.transpose(0, 2, 1).reshape(len(items), 16)  # column-major for GLSL
            data[:, 16:19] = [m.color for _, m in items]
            data[:, 19] = [m.emissive for _, m in items]
            out[shape] = (data, sum(1 for _, m in items if m.cast_shadows))
        return out

    def static_key(self, view: View, data) -> Any:
        """Every instance's matrix, colour and emission, and the view's shadow map: unchanged while nothing
        moves."""
        terrain = self.renderer.terrain_shadow_in(view)
        return (shadow_key(view), None if terrain is None else terrain.key) + tuple(
            (shape, inst.tobytes(), casters) for shape, (inst, casters) in sorted(data.items()))

    def shadow_casters(self, data) -> ShadowCasters | None:
        casting = {shape: inst[:casters] for shape, (inst, casters) in data.items() if casters}
        if not casting:
            return None
        boxes = np.concatenate([instance_bounds(inst) for inst in casting.values()])

        def draw(light_view_proj: np.ndarray) -> None:
            prog = self.renderer.load_program(SHADERS, "shadow_mesh")
            prog["light_view_proj"].write(light_view_proj.T.copy().tobytes())
            for shape, inst in casting.items():
                vao = self._shadow_vao(shape, len(inst))
                self._shadow_instances[shape].write(inst.tobytes())
                vao.render(moderngl.TRIANGLES, instances=len(inst))

        key = tuple((shape, inst[:, :16].tobytes()) for shape, inst in sorted(casting.items()))
        return ShadowCasters(key, boxes, draw)

    def _geometry_of(self, shape: str) -> tuple:
        if shape not in self._geometry:
            verts, idx = primitive(shape)
            vbo, ibo = self.ctx.buffer(verts.tobytes()), self.ctx.buffer(idx.tobytes())
            self._geometry[shape] = ({}, vbo, ibo)
        return self._geometry[shape]

    def _vao(self, shape: str, count: int, defines: tuple[str, ...]) -> moderngl.VertexArray:
        """The shape's VAO for the program variant ``defines`` over its instance buffer (grown as needed)."""
        buf = self._instances.get(shape)
        needed = count * self.INSTANCE_FLOATS * 4
        if buf is None or buf.size < needed:
            if buf is not None:
                buf.release()
                vaos, _, _ = self._geometry[shape]
                for vao in vaos.values():
                    vao.release()
                vaos.clear()
            buf = self.ctx.buffer(reserve=max(needed, 64 * self.INSTANCE_FLOATS * 4))
            self._instances[shape] = buf
        vaos, vbo, ibo = self._geometry_of(shape)
        prog = self.renderer.load_program(SHADERS, "mesh", defines)
        vaos[defines] = current_vao(vaos.get(defines), prog, lambda p: self.ctx.vertex_array(
            p, [(vbo, "3f 3f", "in_position", "in_normal"), (buf, "4f 4f 4f 4f 4f/i", "m0", "m1", "m2", "m3",
                                                             "in_color")], ibo))
        return vaos[defines]

    def _shadow_vao(self, shape: str, count: int) -> moderngl.VertexArray:
        """The shape's depth-only VAO over its shadow instance buffer (grown as needed)."""
        buf = self._shadow_instances.get(shape)
        needed = count * self.INSTANCE_FLOATS * 4
        if buf is None or buf.size < needed:
            if buf is not None:
                buf.release()
                self._shadow_vaos.pop(shape).release()
            buf = self._shadow_instances[shape] = self.ctx.buffer(reserve=max(needed, 64 * self.INSTANCE_FLOATS * 4))
        prog = self.renderer.load_program(SHADERS, "shadow_mesh")
        _, vbo, ibo = self._geometry_of(shape)
        self._shadow_vaos[shape] = current_vao(self._shadow_vaos.get(shape), prog, lambda p: self.ctx.vertex_array(
            p, [(vbo, "3f 12x", "in_position"), (buf, "4f 4f 4f 4f 16x/i", "m0", "m1", "m2", "m3")], ibo))
        return self._shadow_vaos[shape]

    def add_passes(self, graph, view: View, data) -> None:
        if not data:
            return
        shadow = view.extra.get("shadow")

        def setup(b):
            opaque_setup(view)(b)
            read_shadow(b, view)

        def execute(pc):
            fbo = self.renderer.framebuffer(pc.get(view.color), pc.get(view.depth))
            fbo.use()
            self.ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
            self.ctx.disable(moderngl.BLEND)
            lighting = lighting_uniforms(self.renderer, view)
            shadow_defines, shadow_uniforms = receiver_uniforms(shadow, pc)
            terrain_defines, terrain_uniforms = terrain_receiver(self.renderer.terrain_shadow_in(view), self.ctx)
            defines = (("FOG",) if lighting["fog_density"] > 0.0 else ()) + shadow_defines + terrain_defines
            set_uniforms(self.renderer.load_program(SHADERS, "mesh", defines), **lighting, **shadow_uniforms,
                         **terrain_uniforms)
            for shape, (inst, _) in data.items():
                vao = self._vao(shape, len(inst), defines)
                self._instances[shape].write(inst.tobytes())
                vao.render(moderngl.TRIANGLES, instances=len(inst))
            self.ctx.disable(moderngl.CULL_FACE)

        graph.add_pass(f"meshes.{view.name}", setup, execute)

    def release(self) -> None:
        for vaos, vbo, ibo in self._geometry.values():
            for obj in (*vaos.values(), vbo, ibo):
                obj.release()
        for obj in (*self._instances.values(), *self._shadow_instances.values(), *self._shadow_vaos.values()):
            obj.release()
        self._geometry.clear()
        self._instances.clear()
        self._shadow_instances.clear()
        self._shadow_vaos.clear()


def instance_bounds(inst: np.ndarray) -> np.ndarray:
    """(n, 2, 3) float64: the world box (min, max corners) of each instance of a unit primitive (inside the
    cube [-0.5, 0.5]³) with the column-major model matrices in ``inst[:, :16]``."""
    columns = inst[:, :16].reshape(len(inst), 4, 4).astype(np.float64)  # row j: the matrix's column j
    centre = columns[:, 3, :3]
    half = 0.5 * np.abs(columns[:, :3, :3]).sum(axis=1)
    return np.stack([centre - half, centre + half], axis=1)


def shadow_key(view: View) -> Any:
    """What a shadow-receiving feature's static key includes: the content of the view's shadow map and how
    receivers read it (filter, normal offset, fade distance: ``[render]`` settings a hot reload may change while
    the map stays the same)."""
    shadow = view.extra.get("shadow")
    return None if shadow is None else (shadow.key, shadow.soft, shadow.normal_offset, shadow.distance)


# ----------------------------------------------------------- tone map, composite
def _fullscreen(renderer: Renderer, frag: str, defines: tuple[str, ...] = ()) -> moderngl.VertexArray:
    from engine.render.renderer import _with_defines, shader_source

    cache = renderer.fullscreen_vaos
    vao = cache.get((frag, defines))
    if vao is None:
        prog = renderer.program(shader_source(SHADERS / "fullscreen.vert"),
                                _with_defines(shader_source(SHADERS / frag), defines))
        vao = renderer.ctx.vertex_array(prog, [])
        cache[(frag, defines)] = vao
    return vao


def add_texture(renderer: Renderer, target: moderngl.Texture, texture: moderngl.Texture, matrix: np.ndarray,
                region: tuple[int, int, int, int]) -> None:
    """Add ``matrix`` · ``texture`` (3 × 3, its columns multiply the texture's channels; the texture sampled
    bilinearly, upsampled when smaller) onto ``target`` inside ``region`` (a scissor box in the target's
    pixels): an additive full-screen triangle (color_layer.frag)."""
    ctx = renderer.ctx
    fbo = renderer.framebuffer(target)
    fbo.scissor = region
    fbo.use()
    ctx.disable(moderngl.DEPTH_TEST)
    ctx.enable(moderngl.BLEND)
    ctx.blend_func = moderngl.ONE, moderngl.ONE
    try:
        vao = _fullscreen(renderer, "color_layer.frag")
        texture.use(0)
        set_uniforms(vao.program, layer=0, layer_matrix=_mat3(matrix))
        vao.render(moderngl.TRIANGLES, vertices=3)
    finally:
        fbo.scissor = None
        ctx.blend_func = moderngl.DEFAULT_BLENDING
        ctx.disable(moderngl.BLEND)


def _mat3(matrix: np.ndarray) -> tuple[float, ...]:
    """A 3 × 3 matrix as a mat3 uniform (column-major)."""
    return tuple(float(v) for v in np.asarray(matrix, np.float64).reshape(3, 3).T.ravel())


def add_color_layer(graph, renderer: Renderer, name: str, view: View, layer: ColorLayer) -> ColorLayer:
    """Declare the pass ``name`` that adds ``layer`` (:class:`engine.render.feature.ColorLayer`) to ``view``'s
    colour: it reads the layer's texture and writes the colour in the layer's region
    (:func:`engine.render.feature.write_view_color`).  It draws the layer with :func:`add_texture`, unless the
    renderer folded the layer into the view's tone map (``layer.folded``: nothing was drawn over it; known when
    the frame executes)."""
    handles: dict[str, Any] = {}

    def setup(b):
        b.read(layer.texture)
        layer.folded = False
        write_view_color(b, view, layer.region)
        view.extra["color_layer"] = (layer, view.color)  # foldable while the colour stays at this version
        handles["color"] = view.color

    def execute(pc):
        if not layer.folded:
            add_texture(renderer, pc.get(handles["color"]), pc.get(layer.texture), layer.matrix, layer.region)

    graph.add_pass(name, setup, execute)
    return layer


def _tonemap_draw(renderer: Renderer, hdr: moderngl.Texture, origin: tuple[int, int], pc=None,
                  layer: ColorLayer | None = None, size: tuple[int, int] = (0, 0)) -> None:
    """tonemap.frag over the bound target's viewport (and scissor): one HDR texel per pixel, ``origin`` being
    the pixel of texel (0, 0).  ``layer``: a colour layer folded into the tone map (the view's ``size``; ``pc``
    resolves its textures): its region is tone-mapped by the ADD_LAYER variant, and the rest (up to four
    rectangles around it) by the plain one, so no pixel is tone-mapped twice."""
    ctx = renderer.ctx
    vao = _fullscreen(renderer, "tonemap.frag")
    hdr.use(0)
    set_uniforms(vao.program, hdr=0, exposure=renderer.settings.exposure, origin=origin)
    if layer is None:
        vao.render(moderngl.TRIANGLES, vertices=3)
        return
    outer = ctx.scissor  # the caller's (a partial present's rectangle), or None: the viewport
    ox, oy, ow, oh = outer if outer is not None else ctx.viewport
    rx, ry, rw, rh = layer.region
    x0, y0 = max(rx + origin[0], ox), max(ry + origin[1], oy)
    x1, y1 = min(rx + origin[0] + rw, ox + ow), min(ry + origin[1] + rh, oy + oh)
    if x1 <= x0 or y1 <= y0:
        vao.render(moderngl.TRIANGLES, vertices=3)
        return
    around = [(ox, oy, ow, y0 - oy), (ox, y1, ow, oy + oh - y1), (ox, y0, x0 - ox, y1 - y0),
              (x1, y0, ox + ow - x1, y1 - y0)]  # below, above, left, right of the layer's box
    try:
        for box in around:
            if box[2] > 0 and box[3] > 0:
                ctx.scissor = box
                vao.render(moderngl.TRIANGLES, vertices=3)
        added = _fullscreen(renderer, "tonemap.frag", ("ADD_LAYER",))
        pc.get(layer.texture).use(1)
        set_uniforms(added.program, hdr=0, layer=1, exposure=renderer.settings.exposure,
                     origin=origin, view_size=(float(size[0]), float(size[1])), layer_matrix=_mat3(layer.matrix))
        ctx.scissor = (x0, y0, x1 - x0, y1 - y0)
        added.render(moderngl.TRIANGLES, vertices=3)
    finally:
        ctx.scissor = outer


def tonemap_execute(renderer: Renderer, pc, view: View, ldr_handle, source=None,
                    layer: ColorLayer | None = None) -> None:
    """Tone-map a view's HDR colour (or ``source``'s, of the view's size) at the view's own size into an 8-bit
    display-referred target; ``layer``: a colour layer folded in (Renderer._fold_layer)."""
    fbo = renderer.framebuffer(pc.get(ldr_handle))
    fbo.use()
    renderer.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
    fbo.viewport = (0, 0, view.width, view.height)
    _tonemap_draw(renderer, pc.get(view.color if source is None else source), (0, 0), pc, layer,
                  (view.width, view.height))


def present_execute(renderer: Renderer, pc, view: View, final_handle, first: bool, ldr_handle=None,
                    kept=None, layer: ColorLayer | None = None, source=None) -> None:
    """Put a view into its rectangle of the window image (with a frame when partial): tone-map its HDR
    colour there, or, when it was already tone-mapped at a smaller size (``ldr_handle``), upscale it
    bilinearly.  ``kept`` = (handle, (x, y, w, h)): a view presented whole over its restored static layer
    (Renderer._partial_present) copies the layer's tone-mapped picture (a memory copy) and tone-maps only
    that rectangle, where passes wrote over the layer.  ``layer``: a colour layer folded into the tone map;
    ``source``: the HDR colour to tone-map instead of the view's (its kept static layer, Renderer._present_source)."""
    hdr = view.color if source is None else source
    ctx = renderer.ctx
    fbo = renderer.framebuffer(pc.get(final_handle))
    fbo.use()
    ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
    if kept is not None:
        handle, (rx, ry, rw, rh) = kept
        ctx.copy_framebuffer(fbo, renderer.framebuffer(pc.get(handle)))
        if rw > 0 and rh > 0:
            fbo.scissor = (rx, ry, rw, rh)
            try:
                _tonemap_draw(renderer, pc.get(hdr), (0, 0), pc, layer, (view.width, view.height))
            finally:
                fbo.scissor = None
        return
    x, y, w, h = view.extra["rect"]
    full = (x, y, w, h) == (0, 0, renderer.width, renderer.height)
    if first and not full:
        fbo.clear(0.0, 0.0, 0.0, 1.0)
    if not full:
        fbo.clear(*view.extra["border"], 1.0, viewport=(x - 2, y - 2, w + 4, h + 4))
    fbo.viewport = (x, y, w, h)
    if ldr_handle is None:
        _tonemap_draw(renderer, pc.get(hdr), (x, y), pc, layer, (w, h))  # the view's size is the rectangle's
    else:
        vao = _fullscreen(renderer, "upscale.frag")
        pc.get(ldr_handle).use(0)
        set_uniforms(vao.program, image=0)
        vao.render(moderngl.TRIANGLES, vertices=3)
    fbo.viewport = (0, 0, renderer.width, renderer.height)


def antialias_execute(renderer: Renderer, pc, ldr_handle, target_handle) -> None:
    """FXAA (shaders/fxaa.frag) of a view's tone-mapped picture into a target of the same size."""
    ldr = pc.get(ldr_handle)
    fbo = renderer.framebuffer(pc.get(target_handle))
    fbo.use()
    fbo.viewport = (0, 0, *ldr.size)
    renderer.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
    vao = _fullscreen(renderer, "fxaa.frag")
    ldr.use(0)
    set_uniforms(vao.program, image=0, texel=(1.0 / ldr.size[0], 1.0 / ldr.size[1]))
    vao.render(moderngl.TRIANGLES, vertices=3)


# --------------------------------------------------------------------------- text
def text_image(lines: list[str], size: int, color=(255, 255, 255), background=(0, 0, 0, 150), pad: int = 6):
    """RGBA PIL image of ``lines`` on a translucent box (Pillow's built-in font)."""
    from PIL import Image, ImageDraw

    font = _font(size)
    probe = ImageDraw.Draw(Image.new("RGBA", (1, 1)))
    widths, heights = [], []
    for line in lines:
        l, t, r, b = probe.textbbox((0, 0), line or " ", font=font)
        widths.append(r - l)
        heights.append(max(b - t, size))
    w = max(widths) + 2 * pad
    h = sum(int(hh * 1.25) for hh in heights) + 2 * pad
    img = Image.new("RGBA", (max(w, 1), max(h, 1)), background)
    draw = ImageDraw.Draw(img)
    y = pad
    for line, hh in zip(lines, heights):
        draw.text((pad, y), line, font=font, fill=color)
        y += int(hh * 1.25)
    return img


@lru_cache(maxsize=8)
def _font(size: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: fixed-size bitmap font
        return ImageFont.load_default()


class HudFeature(RenderFeature):
    """Draws the Hud resource (and the profiler when toggled) over the composited frame."""

    name = "hud"
    phase = OVERLAY

    FPS_REFRESH_SECONDS = 0.25  # the FPS readout changes at most 4 times a second (readable; no text re-render per frame)

    def __init__(self, renderer: Renderer) -> None:
        super().__init__(renderer)
        self._textures: dict[tuple, moderngl.Texture] = {}
        self._vao: moderngl.VertexArray | None = None
        self._fps_text, self._fps_time = "FPS   --", -1e9

    def _fps_line(self) -> str:
        now = time.perf_counter()
        if now - self._fps_time >= self.FPS_REFRESH_SECONDS:
            fps = self.renderer.fps
            self._fps_text, self._fps_time = (f"FPS {fps:5.1f}" if fps else "FPS   --"), now
        return self._fps_text

    def extract(self, world) -> list[tuple]:
        items: list[tuple] = []
        hud = world.try_resource(Hud)
        if hud is not None:
            lines = list(hud.lines)
            if hud.show_fps:
                lines.append(self._fps_line())
            if lines:
                items.append(("top_left", tuple(lines), 16))
            if hud.center:
                items.append(("center", tuple(hud.center.split("\n")), 34))
            if hud.show_help and hud.help:
                items.append(("help", tuple(hud.help), 16))
        status = world.try_resource(_reload_status())
        if status is not None and status.errors:
            lines = ("config error - the last good config stays in force until the file is fixed:",
                     *status.errors[:12])
            items.append(("bottom_left", lines, 14, (255, 120, 110)))
        elif status is not None and status.warnings:
            lines = ("config warning - legal, but probably not meant:", *status.warnings[:6])
            items.append(("bottom_left", lines, 14, (255, 210, 90)))
        if self.renderer.show_profiler:
            t = self.renderer.timer
            rows = [f"{name:<28s}{ms:7.2f} ms" for name, ms in sorted(t.last.items(), key=lambda kv: -kv[1])[:14]]
            scale = f"render scale {self.renderer.render_scale:.2f}"
            if self.renderer.settings.dynamic_resolution:
                scale += f" (dynamic, {self.renderer.settings.target_fps:g} fps)"
            items.append(("top_right", ("profiler (F3)", scale, *rows), 13))
        return items

    def _texture(self, lines: tuple, size: int, color=(255, 255, 255)) -> moderngl.Texture:
        key = (lines, size, color)
        tex = self._textures.get(key)
        if tex is None:
            if len(self._textures) > 32:
                for old in self._textures.values():
                    old.release()
                self._textures.clear()
            img = text_image(list(lines), size, color)
            tex = self.ctx.texture(img.size, 4, img.tobytes())
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._textures[key] = tex
        return tex

    def add_passes(self, graph, view: View, data) -> None:
        if not data:
            return

        def setup(b):
            view.color = b.write(view.color)

        def execute(pc):
            r = self.renderer
            fbo = r.framebuffer(pc.get(view.color))
            fbo.use()
            self.ctx.disable(moderngl.DEPTH_TEST)
            self.ctx.enable(moderngl.BLEND)
            self.ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
            prog = r.load_program(SHADERS, "sprite")
            vao = self._vao = current_vao(self._vao, prog, lambda p: self.ctx.vertex_array(p, []))
            for where, lines, size, *color in data:
                tex = self._texture(lines, size, *color)
                w, h = tex.size
                x, y = _anchor(where, w, h, r.width, r.height)
                tex.use(0)
                set_uniforms(prog, image=0, rect=(x, y, w, h), screen=(r.width, r.height))
                vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
            self.ctx.disable(moderngl.BLEND)

        graph.add_pass("hud", setup, execute)

    def release(self) -> None:
        for tex in self._textures.values():
            tex.release()
        self._textures.clear()
        if self._vao is not None:
            self._vao.release()
            self._vao = None


def _reload_status():
    from engine.reload import ReloadStatus

    return ReloadStatus


def _anchor(where: str, w: int, h: int, sw: int, sh: int) -> tuple[int, int]:
    margin = 8
    if where == "top_left":
        return margin, sh - h - margin
    if where == "top_right":
        return sw - w - margin, sh - h - margin
    if where == "bottom_left":
        return margin, margin
    if where == "center":
        return (sw - w) // 2, (sh - h) // 2
    return (sw - w) // 2, margin  # help: bottom centre
