"""GrassField rendering: instanced levels 0-3, the level-4 LOD cache (cached cell images) and the level-5 band.

Per field and view, one opaque pass draws the :class:`~systems.grass_field.frame.FramePlan` decided on the CPU:

* levels 0-3: one multi-draw indirect call per level and draw group (tubes, leaves, lines at level 2, dots at
  level 3), one command per plant variant: the variant's own vertices and primitives, without the padding a
  shared topology needs (geometry.compact_mesh), and its plants as instances.  The closed tubes of levels 0-1
  (cylinder, square prism) are drawn with back faces culled.  Each frame the plan's plants (per level, those
  of its cells that the frustum can see, nearest first) are gathered into per-instance records grouped by
  variant (see ``shaders/plant.vert``).  Before GL 4.3 each command is a draw of its own;
* level 4: one instanced draw of all level-4 rectangles; their images come from the LOD cache: each cell
  layout's level-3 grass rendered at 12 views into an RGBA atlas (offscreen framebuffer, transparent
  background) once, before the first frame that needs it, then reused; with ``disk_cache`` the atlas is
  stored on disk keyed by :func:`~systems.grass_field.impostor.cache_key` so a restart skips baking;
* level 5: one draw of the visible band sides; each viewer cell's 12 band images are baked (from the level-4
  images of the far cells) when the viewer first needs them and kept in an LRU cache, and the neighbours of
  the viewer's cell are baked ahead, one per frame.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import moderngl
import numpy as np

from components.grass_field import GrassFieldConfig, GrassFieldState
from engine.render.feature import OPAQUE, RenderFeature, View
from engine.render.passes import lighting_uniforms, opaque_setup, set_uniforms
from engine.render.renderer import shader_source
from engine.render.shadows import may_be_shadowed, read_shadow, receiver_uniforms
from engine.render.terrain_shadow import TerrainShadow
from engine.spatial import Transform
from systems.grass_field.frame import FramePlan, band_apothem, band_sector_content, plan_frame
from systems.grass_field.geometry import DRAW_GROUPS, LEVELS, CompactMesh, compact_mesh
from systems.grass_field.impostor import (ATLAS_MIP_LEVELS, AtlasLayout, DiskCache, Progress, atlas_layout,
                                          bake_depth_range, band_side_frame, band_view_proj, bake_view_proj,
                                          box_mipmaps, cache_key,
                                          coverage_mipmaps, impostor_basis, tile_bounds, tile_frame, tile_pixels)
from systems.grass_field.lod import (N_BAND_SIDES, N_VIEWS, CameraInput, ImpostorOrientation, band_distance,
                                     camera_from_view)
from systems.grass_field.simulate import FieldData, ensure_placed

MAX_ATLAS_SIDE = 4096  # texels per side of the cached-image and band atlases (64 MiB of RGBA8 each at most;
# their tiles shrink to fit): the paper preset needs about 1200, the meadow 2600

__all__ = ["GrassFieldFeature", "FieldGpu", "FieldFrame"]

log = logging.getLogger("grass_field")
SHADERS = Path(__file__).parent / "shaders"
TEXTURE_WIDTH = 4096
IMPOSTOR_FLOATS = 10  # centre (3), facing, two views, blend weight, level, the cell's relief, its quarter turns
# draw group (geometry.DRAW_GROUPS) -> (primitive mode, back faces culled): the closed tubes' faces turned away from
# the eye are hidden by those turned towards it, so half their triangles never reach the rasteriser
GROUP_DRAWS = {"tubes": (moderngl.TRIANGLES, True), "leaves": (moderngl.TRIANGLES, False),
               "lines": (moderngl.LINES, False), "points": (moderngl.POINTS, False)}
COMMAND_WORDS = 5  # an indexed indirect command: count, instance count, first index, base vertex, base instance


# how far the light may stray from the one a band was captured with before the band is captured again: the sun's
# direction by this angle (degrees), its colour, the ambient light and the sky colours by this share
BAND_LIGHT_TOLERANCE = (1.0, 0.02)


def light_close(a: tuple, b: tuple, tolerance: tuple[float, float] = BAND_LIGHT_TOLERANCE) -> bool:
    """Whether lights ``a`` and ``b`` (FieldGpu._light: sun direction, sun colour, ambient, sky colours) are within
    ``tolerance`` (degrees between the suns, the largest relative change of a colour or the ambient light)."""
    da, db = np.asarray(a[0], np.float64), np.asarray(b[0], np.float64)
    cos = float(da @ db) / max(float(np.linalg.norm(da) * np.linalg.norm(db)), 1e-12)
    if cos < np.cos(np.radians(tolerance[0])):
        return False
    for x, y in zip((*a[1], a[2], *a[3]), (*b[1], b[2], *b[3])):
        if abs(x - y) > tolerance[1] * max(abs(x), abs(y), 1e-3):
            return False
    return True


def _with_defines(source: str, defines: tuple[str, ...]) -> str:
    """``source`` with ``#define NAME 1`` lines after its ``#version`` line."""
    if not defines:
        return source
    head, _, rest = source.partition("\n")
    return head + "\n" + "".join(f"#define {name} 1\n" for name in defines) + rest


def _write_levels(texture: moderngl.Texture, levels: list[np.ndarray], dtype) -> None:
    """Mip levels 1, 2, … of ``texture`` from the CPU (allocated by GL first, then overwritten)."""
    texture.build_mipmaps(0, len(levels))
    for level, texels in enumerate(levels, start=1):
        texture.write(np.ascontiguousarray(texels, dtype).tobytes(), level=level)


def _data_texture(ctx: moderngl.Context, texels: np.ndarray) -> moderngl.Texture:
    """A 2-D texture holding ``texels`` (n, c) row by row, ``TEXTURE_WIDTH`` texels per row; nearest filtering."""
    texels = np.asarray(texels)
    n, comps = max(1, len(texels)), texels.shape[1]
    w = TEXTURE_WIDTH  # always: the shaders split an index into (column, row) with a mask and a shift
    h = -(-n // w)
    data = np.zeros((w * h, comps), dtype=np.float32)
    data[:len(texels)] = texels
    tex = ctx.texture((w, h), comps, data.tobytes(), dtype="f4")
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    return tex


RECORD_BYTES = 32  # a plant record: the per-instance attributes i_p0, i_p1 of shaders/plant.vert


def plant_records(position: np.ndarray, yaw: np.ndarray, scale: np.ndarray, tint: np.ndarray,
                  sun: np.ndarray | float = 1.0) -> np.ndarray:
    """(N, 8) float32: per plant (x, y, z, scale, cos yaw, sin yaw, tint, sun), the instance attributes of
    ``shaders/plant.vert``; ``sun`` the share of the sun the terrain leaves the plant (its own shadow,
    engine/render/terrain_shadow.py).  The rotation's cosine and sine are taken once per plant here (in float64),
    not per vertex in the shader.  The plant's variant travels beside the records (it picks the indirect
    command, not a vertex attribute)."""
    yaw = np.asarray(yaw, dtype=np.float64)
    out = np.zeros((len(position), 8), dtype=np.float32)
    out[:, :3], out[:, 3] = position, scale
    out[:, 4], out[:, 5], out[:, 6], out[:, 7] = np.cos(yaw), np.sin(yaw), tint, sun
    return out


@dataclass
class FieldFrame:
    """One field as extracted for this frame."""

    entity: int
    cfg: GrassFieldConfig
    state: GrassFieldState  # read only (its random draws key the disk cache)
    data: FieldData
    max_level: int
    debug: bool


@dataclass
class _BandEntry:
    slot: int
    eye: np.ndarray  # (3,) where the 12 images were captured from (cell centre at the viewer's height)
    bottom: float
    top: float
    content: np.ndarray  # (12,) sides with far cells behind them
    apothem: float  # the band's distance from the cell's centre (frame.band_apothem of the views it serves)
    vertices: np.ndarray | None = None  # (12, 6, 5) the sides' triangles, made on first draw


class FieldGpu:
    """The GL resources of one GrassField and its drawing (created lazily by the feature)."""

    def __init__(self, renderer: Any, cfg: GrassFieldConfig, state: GrassFieldState, data: FieldData) -> None:
        self.renderer = renderer
        self.ctx: moderngl.Context = renderer.ctx
        self.cfg, self.state, self.data = cfg, state, data
        # shader variants, compiled on first use: llvmpipe runs both sides of every branch, so the debug view,
        # fog and view blending are compiled in only where they are used (see _program)
        self._programs: dict[tuple[str, bool, bool, bool], moderngl.Program] = {}
        self._vaos: dict[tuple, moderngl.VertexArray] = {}
        for name in ("plant", "band"):  # compiled now, so that a shader error shows when the field appears
            self._program(name)
        placed = data.placed
        ctx = self.ctx
        self.plant_records = plant_records(placed.plant_position, placed.plant_yaw, placed.plant_scale,
                                           placed.plant_tint)
        self.plant_variant = np.asarray(placed.plant_variant, np.int64)
        # the light the band's images (level 5) were captured with, and the terrain shadow the plants' share of the
        # sun was taken from: a new light re-captures the bands once it strays past BAND_LIGHT_TOLERANCE; a new
        # terrain shadow re-takes the plants' share (the level-4 images are unlit: nothing to do for them)
        self._light_key: tuple | None = None
        self._terrain_key: Any = None
        self._terrain_ground: Any = None  # the terrain shadow's key less the sun (TerrainShadow.ground_key)
        self.cell_capacity = max(1, placed.cell_count)
        # the records of the plants drawn this frame, all geometric levels one after the other, each level's by
        # variant (the plan's plant list gathered on the CPU: 32 bytes a plant drawn, rewritten per frame)
        self.instance_buf = ctx.buffer(reserve=max(1, len(self.plant_records)) * RECORD_BYTES)
        # per level: the variants without their shared topology's padding (geometry.compact_mesh), one vertex
        # buffer and one index buffer; a level draws with one indirect command per variant and draw group
        self.meshes: dict[int, CompactMesh] = {m.level: compact_mesh(m) for m in data.meshes}
        self.mesh_vbo = {k: ctx.buffer(m.vertices.tobytes()) for k, m in self.meshes.items()}
        self.mesh_ibo = {k: ctx.buffer(m.index.tobytes()) for k, m in self.meshes.items()}
        # the commands' per-mesh words (index count, first index, base vertex); _upload_plants adds the instances
        self.mesh_commands = np.zeros((LEVELS, len(DRAW_GROUPS), cfg.plant_variants, COMMAND_WORDS), np.uint32)
        for level, mesh in self.meshes.items():
            for g, group in enumerate(DRAW_GROUPS):
                self.mesh_commands[level, g, :, 0] = mesh.count[group]
                self.mesh_commands[level, g, :, 2] = mesh.first[group]
                self.mesh_commands[level, g, :, 3] = mesh.vertex_base
        self.command_buf = ctx.buffer(reserve=2 * self.mesh_commands.nbytes)  # two sets: plain, shadowed
        # multi-draw indirect with base instances (GL 4.3); before it, one draw per variant (rebinding offsets)
        self.multi_draw = self.ctx.version_code >= 430
        # level 4: the LOD cache
        self.frame = tile_frame(cfg.cell_size, data.plant_reach, data.plant_height,
                                np.radians(cfg.impostor_elevation_deg))
        tw, th = tile_pixels(self.frame, cfg)
        max_size = int(ctx.info.get("GL_MAX_TEXTURE_SIZE", 8192))
        self.layout: AtlasLayout = atlas_layout(cfg.cell_variants * N_VIEWS, tw, th, min(max_size, MAX_ATLAS_SIDE))
        self.atlas: moderngl.Texture | None = None
        # beside it, the depth of each texel's grass in its cached view (plant.frag's ATLAS_DEPTH: window depth ·
        # coverage, coverage; rg16f, mip levels box-filtered): where the sun's shadow map is looked up
        self.atlas_depth: moderngl.Texture | None = None
        # and the normal of each texel's grass (its layout's frame; rgba8 (normal / 2 + 1 / 2, normal.y^2) ·
        # coverage, mip levels box-filtered, the coverage the depth image's): the images are unlit, impostor.frag
        # lights them with the frame's light
        self.atlas_normal: moderngl.Texture | None = None
        self.bounds_tex: moderngl.Texture | None = None
        self.baked_views = 0  # cached views rendered (each view of each layout once, unless loaded from disk)
        self.loaded_from_disk = False
        self.disk_path: Path | None = None
        self.impostor_buf = ctx.buffer(reserve=self.cell_capacity * IMPOSTOR_FLOATS * 4)
        self.impostor_shadowed_buf = ctx.buffer(reserve=self.cell_capacity * IMPOSTOR_FLOATS * 4)
        self.shadowed_rectangles = 0  # level-4 rectangles of the last draw() drawn with the sun shadow look-up
        # level-4 rectangles write the depth of their texels' grass (GRASS_DEPTH; off: the rectangle's, in front of
        # the whole cell, as the paper drew them; A/B, tests)
        self.grass_depth = True
        # level 5: the band
        self.band_entries: OrderedDict[tuple[int, int], _BandEntry] = OrderedDict()
        self.band_layout: AtlasLayout | None = None
        self.band_tex: moderngl.Texture | None = None
        # each band texel's distance from the eye that captured it (0 where no grass, filtered like the colour): the
        # band is fogged per texel at the distance of its grass.  r16f: its 1/1000 steps are far finer than the
        # fog needs, at half the memory of r32f (9 MB beside the colour's 18 MB for a 1280-pixel-wide view)
        self.band_distance: moderngl.Texture | None = None
        self.band_fbo: moderngl.Framebuffer | None = None
        self.band_depth: moderngl.Renderbuffer | None = None
        self.band_bakes = 0  # viewer cells whose 12 images were captured
        # per viewer (a view's name; each camera moves and holds its height step on its own):
        self._band_eyes: dict = {}  # the viewer's last (x, z): the direction it moves in
        self._band_levels: dict = {}  # the eye-height step in use (see _band_key)
        self.band_buf = ctx.buffer(reserve=N_BAND_SIDES * 6 * 5 * 4)
        self._band_content: dict[tuple[int, float], np.ndarray] = {}
        self.draw_calls = 0  # draw calls of the last draw() (bakes excluded)
        self.shadowed_plants = 0  # plants of the last draw() drawn with the sun shadow look-up
        self._released = False

    # ------------------------------------------------------------------------------ programs, arrays
    def _program(self, name: str, *, debug: bool = False, fog: bool = False,
                 band_distance: bool = False, terrain_shadow: bool = False,
                 shadows: tuple[str, ...] = (), atlas_depth: bool = False,
                 grass_depth: bool = False) -> moderngl.Program:
        """``name.vert`` + ``name.frag`` compiled with the defines DEBUG_LEVELS (the debug view), FOG (the view
        has fog), BAND_DISTANCE (the band's capture: the level-4 rectangles also write their distance from the
        eye), TERRAIN_SHADOW (the level-4 rectangles read the terrain's shadow), ``shadows`` (the plants and the
        level-4 rectangles read the sun's shadow map: engine/render/shadows.py's defines), ATLAS_DEPTH (the LOD
        cache's bake also writes each texel's depth), GRASS_DEPTH (the level-4 rectangles write their texels'
        grass's depth) and, for the level-4 rectangles, BLEND_VIEWS (``blend_views``); shared through the
        renderer."""
        key = (name, debug, fog, band_distance, terrain_shadow, shadows, atlas_depth, grass_depth)
        prog = self._programs.get(key)
        if prog is not None:
            return prog
        defines = tuple(d for d, on in (("DEBUG_LEVELS", debug), ("FOG", fog), ("BAND_DISTANCE", band_distance),
                                        ("TERRAIN_SHADOW", terrain_shadow), ("ATLAS_DEPTH", atlas_depth),
                                        ("GRASS_DEPTH", grass_depth),
                                        ("BLEND_VIEWS", name == "impostor" and self.cfg.blend_views)) if on)
        defines += shadows
        try:
            prog = self.renderer.program(_with_defines(shader_source(SHADERS / f"{name}.vert"), defines),
                                         _with_defines(shader_source(SHADERS / f"{name}.frag"), defines))
        except moderngl.Error as exc:
            raise RuntimeError(f"shader '{name}' {defines} in {SHADERS} failed to compile:\n{exc}") from None
        self._programs[key] = prog
        return prog

    def _vao(self, prog: moderngl.Program, what: tuple) -> moderngl.VertexArray:
        """The vertex array of ``what`` (("mesh", level, records buffer), ("impostor", instance buffer) or
        ("band",)) for ``prog``."""
        key = (prog.glo, *(x.glo if isinstance(x, moderngl.Buffer) else x for x in what))
        vao = self._vaos.get(key)
        if vao is None:
            if what[0] == "mesh":
                level, records = what[1:]
                vao = self.ctx.vertex_array(prog, [(self.mesh_vbo[level], "4f 4f", "in_a", "in_b"),
                                                   (records, "4f 4f /i", "i_p0", "i_p1")],
                                            index_buffer=self.mesh_ibo[level], index_element_size=4)
            elif what[0] == "impostor":  # i_level feeds only the debug view, i_relief GRASS_DEPTH: absent from
                # the other variants
                vao = self.ctx.vertex_array(prog, [(what[1], "3f 1f 2f 1f 1f 1f 1f /i", "i_centre", "i_face",
                                                    "i_tiles", "i_blend", "i_level", "i_relief", "i_turn")],
                                            skip_errors=True)
            else:
                vao = self.ctx.vertex_array(prog, [(self.band_buf, "3f 2f", "in_position", "in_uv")])
            self._vaos[key] = vao
        return vao

    # ----------------------------------------------------------------------------------- shared state
    def band_content(self, cell: int, apothem: float) -> np.ndarray:
        """Which sides of the band of ``apothem`` around ``cell`` have far cells behind them (cached)."""
        found = self._band_content.get((cell, apothem))
        if found is None:
            found = band_sector_content(self.data, cell, apothem)
            self._band_content[(cell, apothem)] = found
        return found

    def _lighting(self, view: View | None) -> dict[str, Any]:
        r = self.renderer
        if view is not None:
            return lighting_uniforms(r, view)
        s = r.settings
        return dict(sun_dir=tuple(r.sun_direction), sun_color=tuple(r.sun_color), ambient=r.ambient,
                    sky_top=tuple(s.sky_top), sky_horizon=tuple(s.sky_horizon), fog_density=0.0)

    def _plant_uniforms(self) -> dict[str, Any]:
        cfg = self.cfg
        return dict(stem_color=tuple(cfg.stem_color), leaf_base_color=tuple(cfg.leaf_base_color),
                    leaf_tip_color=tuple(cfg.leaf_tip_color))

    def _upload_plants(self, buffer: moderngl.Buffer, records: np.ndarray, variants_of: np.ndarray,
                       listed: np.ndarray, counts: list[int], receives: np.ndarray | None = None) -> np.ndarray:
        """Write the records of the plants ``listed`` (the levels' plants one after the other, ``counts`` per
        level; ``variants_of`` every record's plant variant) into ``buffer`` grouped by variant within each level
        (stable: a level's near-first order holds within each variant), and return the indirect commands
        (levels × draw groups × variants, :data:`COMMAND_WORDS`): the meshes' part made once, the instance counts
        and base instances per call.  With ``receives`` (a bool per listed plant: a sun shadow may reach it)
        the plants are split into two sets, and the commands are (2, levels, draw groups, variants, words):
        set 0 the plants drawn plainly, set 1 those drawn with the shadow look-up."""
        variants = self.cfg.plant_variants
        sets = 1 if receives is None else 2
        key = variants_of[listed] if receives is None else variants_of[listed] + variants * receives
        order, per_key, offset = [], np.zeros((LEVELS, sets * variants), np.int64), 0
        for level, n in enumerate(counts):
            k = key[offset:offset + n]
            order.append(offset + np.argsort(k, kind="stable"))
            per_key[level] = np.bincount(k, minlength=sets * variants)
            offset += n
        buffer.write(records[listed[np.concatenate(order)]])
        base = (np.cumsum(per_key.ravel()) - per_key.ravel()).reshape(LEVELS, sets, variants).transpose(1, 0, 2)
        commands = np.repeat(self.mesh_commands[None], sets, axis=0)
        commands[..., 1] = per_key.reshape(LEVELS, sets, variants).transpose(1, 0, 2)[:, :, None, :]
        commands[..., 4] = base[:, :, None, :]
        return commands if receives is not None else commands[0]

    def _receivers(self, shadow, listed: np.ndarray) -> np.ndarray | None:
        """Which listed plants a sun shadow of this frame may reach (None without a shadow map or where it
        reaches none): per cell, by its box (the cell's plants with their reach and height) against the casters'
        (receiver culling)."""
        if shadow is None or not len(listed):
            return None
        cell_of = listed // self.data.placed.plants_per_cell
        cells = np.unique(cell_of)
        reached = np.zeros(self.data.placed.cell_count, bool)
        reached[cells] = self._cells_reached(shadow, cells)
        return reached[cell_of] if reached.any() else None

    def _cells_reached(self, shadow, cells: np.ndarray) -> np.ndarray:
        """(len(cells),) whether a caster's shadow may reach each cell's box (its plants with their reach and
        height; a level-4 rectangle stands for the same grass)."""
        placed, data = self.data.placed, self.data
        centre = placed.cell_centre[cells]
        lo = np.column_stack([centre[:, 0] - data.cell_radius, placed.cell_ground[cells, 0],
                              centre[:, 2] - data.cell_radius])
        hi = np.column_stack([centre[:, 0] + data.cell_radius, placed.cell_ground[cells, 1] + data.plant_height,
                              centre[:, 2] + data.cell_radius])
        return may_be_shadowed(shadow, np.stack([lo, hi], axis=1))

    def _draw_plants(self, prog: moderngl.Program, records: moderngl.Buffer, commands: np.ndarray,
                     levels: range | list[int], set_level=None, command_set: int | None = None) -> None:
        """Draw the plants of ``levels`` uploaded by :meth:`_upload_plants`: per level and draw group one
        multi-draw indirect call (one command per variant), or one draw per variant before GL 4.3.
        ``command_set``: which set of a split upload to draw (the caller wrote all of ``commands`` into the
        command buffer once: rewriting it between the sets' draws would wait for the first set's); None: one
        set, written here."""
        first_command = 0
        if command_set is None:
            if self.multi_draw:
                self.command_buf.write(commands.tobytes())
        else:
            first_command = command_set * int(np.prod(commands.shape[1:4]))
            commands = commands[command_set]
        ctx = self.ctx
        variants = commands.shape[2]
        for level in levels:
            if not commands[level, 0, :, 1].any():
                continue
            if set_level is not None:
                set_level(level)
            vao = self._vao(prog, ("mesh", level, records))
            for g, group in enumerate(DRAW_GROUPS):
                if group not in self.meshes[level].groups:
                    continue
                mode, cull = GROUP_DRAWS[group]
                if cull:
                    ctx.front_face, ctx.cull_face = "ccw", "back"
                    ctx.enable(moderngl.CULL_FACE)
                if self.multi_draw:
                    vao.render_indirect(self.command_buf, mode, count=variants,
                                        first=first_command + (level * len(DRAW_GROUPS) + g) * variants)
                    self.draw_calls += 1
                else:
                    for count, instances, first, base_vertex, base_instance in commands[level, g].tolist():
                        if not (count and instances):
                            continue
                        for name, buf, at, divisor in (("in_a", self.mesh_vbo[level], 32 * base_vertex, 0),
                                                       ("in_b", self.mesh_vbo[level], 32 * base_vertex + 16, 0),
                                                       ("i_p0", records, RECORD_BYTES * base_instance, 1),
                                                       ("i_p1", records, RECORD_BYTES * base_instance + 16, 1)):
                            vao.bind(prog[name].location, "f", buf, "4f", offset=at, stride=32,  # 8 floats both
                                     divisor=divisor)
                        vao.render(mode, vertices=count, first=first, instances=instances)
                        self.draw_calls += 1
                if cull:
                    ctx.disable(moderngl.CULL_FACE)

    # ------------------------------------------------------------------------------- level 4 (cache)
    def _cache_extra(self) -> dict[str, Any]:
        """What the cached images depend on beyond the config and its random draws (the disk cache's key): their
        tiles' size and framing.  Not the light: they hold the albedo and the normal, lit when drawn."""
        return {"tile": [self.layout.tile_w, self.layout.tile_h, self.layout.cols, self.layout.rows],
                "frame": [self.frame.half_width, self.frame.bottom, self.frame.top, self.frame.depth]}

    def _light(self) -> tuple:
        """The light the band's captures are lit with (sun direction and colour, ambient, sky colours)."""
        light = self._lighting(None)
        return (tuple(float(x) for x in light["sun_dir"]), tuple(float(x) for x in light["sun_color"]),
                float(light["ambient"]), tuple(float(x) for x in (*light["sky_top"], *light["sky_horizon"])))

    def ensure_impostors(self) -> None:
        """Bake the 12 views of every cell layout into the atlas once (or load them from the disk cache)."""
        if self.atlas is not None:
            return
        w, h = self.layout.size
        key = cache_key(self.cfg, self.state, self._cache_extra())
        disk = DiskCache(self.cfg.cache_dir) if self.cfg.disk_cache else None
        found = disk.load(key, (h, w, 4), (h, w, 2), (h, w, 4)) if disk is not None else None
        self.atlas = self.ctx.texture((w, h), 4)
        self.atlas_depth = self.ctx.texture((w, h), 2, dtype="f2")
        self.atlas_normal = self.ctx.texture((w, h), 4)
        if found is not None:
            image, depth, normal = found
            self.loaded_from_disk = True
            self.disk_path = disk.path(key)
            self.atlas.write(np.ascontiguousarray(image).tobytes())
            self.atlas_depth.write(np.ascontiguousarray(depth).tobytes())
            self.atlas_normal.write(np.ascontiguousarray(normal).tobytes())
        else:
            image, depth, normal = self._bake_atlas()
            if disk is not None:
                self.disk_path = disk.store(key, image, depth, normal)
        self.bounds_tex = _data_texture(self.ctx, tile_bounds(image, self.layout))
        _write_levels(self.atlas, coverage_mipmaps(image, ATLAS_MIP_LEVELS), np.uint8)
        # the depth's and the normal's levels: plain box filters of (depth, 1) · coverage and (normal / 2 + 1 / 2,
        # normal.y^2) · coverage over the colour levels' texels, so their ratios are the covered texels' mean depth
        # and normal wherever the colour's coverage-scaled alpha passes (GL's generated levels filter other texels
        # at odd sizes: grass in colour, none in depth, read as depth 0)
        _write_levels(self.atlas_depth, box_mipmaps(depth, ATLAS_MIP_LEVELS), np.float16)
        _write_levels(self.atlas_normal, [np.round(level).astype(np.uint8)
                                          for level in box_mipmaps(normal, ATLAS_MIP_LEVELS)], np.uint8)
        # bilinear within the nearest mip level: trilinear filtering fetches twice the texels of an alpha-tested
        # image for a blend the coverage-preserving levels barely need (-25 % of the level-4 pass on llvmpipe)
        for tex in (self.atlas, self.atlas_depth, self.atlas_normal):
            tex.filter = (moderngl.LINEAR_MIPMAP_NEAREST, moderngl.LINEAR)
            tex.repeat_x = tex.repeat_y = False

    def _bake_atlas(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Render level-3 grass of each layout at 12 views (every 30°) with a transparent background, unlit; (the
        albedo atlas, rgba8; its depth image, float16 (window depth, 1) where grass is drawn; its normal image,
        rgba8 (normal / 2 + 1 / 2, normal.y^2) in the layout's frame where grass is drawn)."""
        ctx, cfg, state = self.ctx, self.cfg, self.state
        w, h = self.layout.size
        depth = ctx.depth_renderbuffer((w, h))
        fbo = ctx.framebuffer(color_attachments=[self.atlas, self.atlas_depth, self.atlas_normal],
                              depth_attachment=depth)
        layouts = cfg.cell_variants
        n = cfg.plants_per_cell
        offsets = state.layout_offset.reshape(-1, 2)
        local = np.column_stack([offsets[:, 0], np.zeros(len(offsets)), offsets[:, 1]])
        records = plant_records(local, state.layout_yaw.reshape(-1), state.layout_scale.reshape(-1),
                                state.layout_tint.reshape(-1))  # unlit: light and shade come at draw time
        variants_of = np.asarray(state.layout_variant, np.int64).reshape(-1)
        plants = ctx.buffer(reserve=max(1, n) * RECORD_BYTES)
        try:
            fbo.use()
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
            prog = self._program("plant", atlas_depth=True)
            set_uniforms(prog, **self._plant_uniforms())
            progress = Progress("grass_field: baking the LOD cache", layouts * N_VIEWS)
            for k in range(layouts):
                commands = self._upload_plants(plants, records, variants_of, np.arange(k * n, (k + 1) * n),
                                               [0, 0, 0, n])
                for v in range(N_VIEWS):
                    vp = self.layout.viewport(k * N_VIEWS + v)
                    fbo.viewport = vp
                    fbo.scissor = vp
                    _, _, normal = impostor_basis(v * 2.0 * np.pi / N_VIEWS, self.frame.elevation)
                    set_uniforms(prog, view_proj=bake_view_proj(v, self.frame).T.astype(np.float32).copy(),
                                 bake_normal=tuple(normal))
                    self._draw_plants(prog, plants, commands, [3])
                    self.baked_views += 1
                progress.update((k + 1) * N_VIEWS)
            fbo.scissor = None
            raw, raw_depth, raw_normal = self.atlas.read(), self.atlas_depth.read(), self.atlas_normal.read()
        finally:
            fbo.release()
            depth.release()
            plants.release()
        return (np.frombuffer(raw, np.uint8).reshape(h, w, 4).copy(),
                np.frombuffer(raw_depth, np.float16).reshape(h, w, 2).copy(),
                np.frombuffer(raw_normal, np.uint8).reshape(h, w, 4).copy())

    def _impostor_uniforms(self, view_proj: np.ndarray, eye: np.ndarray, ortho: bool) -> dict[str, Any]:
        f, lay = self.frame, self.layout
        return dict(view_proj=view_proj.T.astype(np.float32).copy(), eye=tuple(float(x) for x in eye),
                    ortho=int(ortho), frame=(f.half_width, f.bottom, f.top, f.depth), elevation=f.elevation,
                    atlas=(float(lay.cols), float(lay.tile_w), float(lay.tile_h), float(lay.pad)),
                    atlas_size=tuple(float(x) for x in lay.size), atlas_tex=0, bounds_tex=1)

    def _impostor_instances(self, cells: np.ndarray, face: np.ndarray, views: np.ndarray, blend: np.ndarray,
                            level: int, buffer: moderngl.Buffer | None = None) -> int:
        """Write the rectangles of ``cells`` into ``buffer`` (the impostor buffer by default); how many."""
        data = np.zeros((len(cells), IMPOSTOR_FLOATS), np.float32)
        if len(cells):
            data[:, 0:3] = self.data.placed.cell_centre[cells]
            data[:, 3] = face
            data[:, 4:6] = self.data.cell_variant[cells, None] * N_VIEWS + views
            data[:, 6] = blend
            data[:, 7] = level
            placed = self.data.placed
            data[:, 8] = np.maximum(placed.cell_ground[cells, 1] - placed.cell_centre[cells, 1], 0.0)
            data[:, 9] = self.data.cell_turn[cells]
            (self.impostor_buf if buffer is None else buffer).write(data.tobytes())
        return len(cells)

    # ------------------------------------------------------------------------------------ level 5 (band)
    def _band_key(self, cell: int, camera: CameraInput, viewer=None, apothem: float | None = None,
                  terrain_shadow: bool = True) -> tuple[int, int, float, bool]:
        """(cell, eye height above the cell in steps of half a plant height, the band's apothem: the plan's, or
        :func:`~systems.grass_field.frame.band_apothem` of ``camera``, whether the images hold the terrain's
        shadow: ``terrain_shadow`` and the renderer has one).  The step in use is kept until the eye is
        three quarters of a step away from it (hysteresis: an eye hovering at a step boundary, as a camera
        following a walker does, would otherwise re-bake the band at every crossing); per ``viewer``."""
        ground = float(self.data.placed.cell_centre[cell, 1])
        step = max(0.5 * self.data.plant_height, 1e-6)
        level = (float(camera.position[1]) - ground) / step
        last = self._band_levels.get(viewer)
        if last is None or abs(level - last) > 0.75:
            last = self._band_levels[viewer] = int(np.floor(level + 0.5))
        return (cell, last, band_apothem(self.cfg, self.data, camera) if apothem is None else apothem,
                terrain_shadow and self.renderer.terrain_shadow is not None)

    def ensure_band(self, cell: int, camera: CameraInput, prefetch: int = 1, viewer=None,
                    apothem: float | None = None, terrain_shadow: bool = True) -> _BandEntry:
        """The band images of ``cell`` (baked now if missing), and up to ``prefetch`` neighbours baked ahead:
        those the viewer is heading for (ahead of its motion since the last frame, nearest the heading first),
        so a walk bakes about one cell per cell crossed instead of every neighbour it passes; none while it
        stands still.  ``viewer``: whose motion and height step these are (a view's name); ``terrain_shadow``:
        whether its view receives the terrain's shadow (not where it hides the terrain)."""
        self._band_resolution(camera)
        key = self._band_key(cell, camera, viewer, apothem, terrain_shadow)
        entry = self.band_entries.get(key)
        if entry is None:
            entry = self._bake_band(key, camera)
        self.band_entries.move_to_end(key)
        placed = self.data.placed
        eye = np.asarray(camera.position, dtype=np.float64)[[0, 2]]
        last_eye = self._band_eyes.get(viewer)
        motion = np.zeros(2) if last_eye is None else eye - last_eye
        self._band_eyes[viewer] = eye
        col, row = cell % placed.grid_x, cell // placed.grid_x
        around = [r * placed.grid_x + c for r in range(row - 1, row + 2) for c in range(col - 1, col + 2)
                  if 0 <= r < placed.grid_z and 0 <= c < placed.grid_x and (r, c) != (row, col)]
        offset = placed.cell_centre[around][:, [0, 2]] - placed.cell_centre[cell, [0, 2]]
        heading = offset @ motion / np.maximum(np.linalg.norm(offset, axis=1), 1e-9)
        ahead = [(around[i], *key[1:]) for i in np.argsort(-heading, kind="stable")
                 if heading[i] > 0.5 * np.linalg.norm(motion)]  # within 60 degrees of the heading
        for neighbour in ahead:
            if prefetch <= 0:
                break
            if neighbour in self.band_entries:
                continue
            full = len(self.band_entries) >= self.cfg.band_cache_cells
            if full and next(iter(self.band_entries)) in ahead:
                break  # never evict a cell ahead to bake another
            self._bake_band(neighbour, camera)
            self.band_entries.move_to_end(key)
            prefetch -= 1
        return entry

    def _band_tile_width(self, camera: CameraInput) -> int:
        """Texels across one band side for this view: the side's width on screen seen from the viewer's cell
        (W tan 15° / tan θ: the same at every apothem), times ``band_resolution_scale``."""
        cfg = self.cfg
        half = cfg.merge_distance * np.tan(np.pi / N_BAND_SIDES)
        if camera.ortho_pixels_per_unit is not None:
            per_unit = 256.0 / (2.0 * half)
        else:
            per_unit = camera.width / (2.0 * cfg.merge_distance * camera.tan_half_fov)
        return int(np.clip(np.ceil(2.0 * half * per_unit * cfg.band_resolution_scale), 16, 2048))

    def _band_resolution(self, camera: CameraInput) -> None:
        """A view that needs band images over 1.5 times as wide as the atlas holds (a window made larger) gets a
        new atlas at its resolution; the cached bands are baked again as they are needed.  It never shrinks, so
        two views of different sizes do not make it thrash."""
        if self.band_tex is None or self._band_tile_width(camera) <= 1.5 * self.band_layout.tile_w:
            return
        for obj in (self.band_tex, self.band_distance, self.band_fbo, self.band_depth):
            obj.release()
        self.band_tex = self.band_distance = self.band_fbo = self.band_depth = None
        self.band_entries.clear()

    def _band_atlas(self, camera: CameraInput, height_ratio: float) -> None:
        if self.band_tex is not None:
            return
        cfg = self.cfg
        tw = self._band_tile_width(camera)
        th = int(np.clip(np.ceil(tw * height_ratio * 1.25), 8, 512))
        max_size = min(int(self.ctx.info.get("GL_MAX_TEXTURE_SIZE", 8192)), MAX_ATLAS_SIDE)
        self.band_layout = atlas_layout(cfg.band_cache_cells * N_BAND_SIDES, tw, th, max_size, pad=1)
        self.band_tex = self.ctx.texture(self.band_layout.size, 4)
        self.band_tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.band_tex.repeat_x = self.band_tex.repeat_y = False
        self.band_distance = self.ctx.texture(self.band_layout.size, 1, dtype="f2")
        self.band_distance.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.band_distance.repeat_x = self.band_distance.repeat_y = False
        self.band_depth = self.ctx.depth_renderbuffer(self.band_layout.size)
        self.band_fbo = self.ctx.framebuffer(color_attachments=[self.band_tex, self.band_distance],
                                             depth_attachment=self.band_depth)
        self.band_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)

    def _bake_band(self, key: tuple[int, int, float, bool], camera: CameraInput) -> _BandEntry:
        """Capture the far surroundings of cell ``key[0]`` in 12 directions from its centre (section 6)."""
        cfg, placed = self.cfg, self.data.placed
        cell = key[0]
        centre = placed.cell_centre[cell]
        step = max(0.5 * self.data.plant_height, 1e-6)
        eye = np.array([centre[0], centre[1] + key[1] * step, centre[2]])
        apothem = key[2]
        far = np.flatnonzero((band_distance(placed.cell_centre[:, [0, 2]], centre[[0, 2]]) >= apothem)
                             & ~self.data.bare)
        content = self.band_content(cell, apothem)
        bottom, top = eye[1] - 1.0, eye[1] + 1.0
        if len(far):
            depth = band_distance(placed.cell_centre[far][:, [0, 2]], eye[[0, 2]]) - self.data.cell_radius
            scale = apothem / np.maximum(depth, 0.5 * apothem)
            lo = placed.cell_ground[far, 0] - 0.05 * self.data.plant_height
            hi = placed.cell_ground[far, 1] + self.data.plant_height
            bottom = float(min((eye[1] + (lo - eye[1]) * scale).min(), eye[1] - 1e-3))
            top = float(max((eye[1] + (hi - eye[1]) * scale).max(), eye[1] + 1e-3))
        half = apothem * np.tan(np.pi / N_BAND_SIDES)
        self._band_atlas(camera, (top - bottom) / (2.0 * half))
        if key in self.band_entries:
            slot = self.band_entries.pop(key).slot
        elif len(self.band_entries) >= cfg.band_cache_cells:
            slot = self.band_entries.popitem(last=False)[1].slot  # the least recently used
        else:
            slot = len(self.band_entries)
        entry = _BandEntry(slot, eye, bottom, top, content, apothem)
        self.band_entries[key] = entry
        self._render_band(entry, far, self.renderer.terrain_shadow if key[3] else None)
        self.band_bakes += 1
        return entry

    def _render_band(self, entry: _BandEntry, far: np.ndarray, terrain: TerrainShadow | None = None) -> None:
        placed = self.data.placed
        rel = placed.cell_centre[far][:, [0, 2]] - entry.eye[[0, 2]]
        face = np.arctan2(-rel[:, 1], -rel[:, 0])
        step = 2.0 * np.pi / N_VIEWS
        view = np.mod(np.round(np.mod(face, 2.0 * np.pi) / step).astype(np.int64) - 3 * self.data.cell_turn[far],
                      N_VIEWS)
        count = self._impostor_instances(far, face, np.stack([view, view], axis=1), np.zeros(len(far)), 5)
        fbo, lay = self.band_fbo, self.band_layout
        reach = np.linalg.norm(placed.cell_centre[:, [0, 2]] - entry.eye[[0, 2]], axis=1).max()
        fbo.use()
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
        prog = self._program("impostor", band_distance=True, terrain_shadow=terrain is not None)
        set_uniforms(prog, **self._lighting(None), **self._terrain_uniforms(terrain), **self._depth_uniforms(False))
        vao = self._vao(prog, ("impostor", self.impostor_buf))
        self.atlas.use(0)
        self.bounds_tex.use(1)
        self.atlas_depth.use(2)
        self.atlas_normal.use(3)
        for side in range(N_BAND_SIDES):
            vp = lay.viewport(entry.slot * N_BAND_SIDES + side)
            fbo.viewport = vp
            fbo.scissor = vp
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0, viewport=vp)
            if not entry.content[side] or count == 0:
                continue
            vp_mat = band_view_proj(entry.eye, entry.apothem, side, entry.bottom, entry.top,
                                    reach + 2.0 * self.data.cell_radius)
            set_uniforms(prog, **self._impostor_uniforms(vp_mat, entry.eye, False), camera_pos=tuple(entry.eye))
            vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=count)
        fbo.scissor = None

    def _band_vertices(self, entry: _BandEntry) -> np.ndarray:
        """(12, 6, 5) float32: two triangles per band side, position and atlas uv (made once per entry)."""
        if entry.vertices is None:
            lay = self.band_layout
            w, h = lay.size
            sides = np.arange(N_BAND_SIDES)
            normal = np.stack([np.cos(sides * 2.0 * np.pi / N_BAND_SIDES), np.sin(sides * 2.0 * np.pi / N_BAND_SIDES)], 1)
            right = np.stack([-normal[:, 1], normal[:, 0]], axis=1)
            _, _, half = band_side_frame(entry.eye, entry.apothem, 0)
            mid = entry.eye[[0, 2]] + normal * entry.apothem
            cx = np.array([0, 1, 0, 1, 1, 0], dtype=np.float64)
            cy = np.array([0, 0, 1, 0, 1, 1], dtype=np.float64)
            xz = mid[:, None, :] + ((2.0 * cx - 1.0) * half)[None, :, None] * right[:, None, :]
            tiles = np.array([lay.viewport(entry.slot * N_BAND_SIDES + k) for k in sides], dtype=np.float64)
            out = np.empty((N_BAND_SIDES, 6, 5), dtype=np.float32)
            out[..., 0], out[..., 2] = xz[..., 0], xz[..., 1]
            out[..., 1] = np.where(cy == 0, entry.bottom, entry.top)[None, :]
            out[..., 3] = (tiles[:, None, 0] + cx[None, :] * tiles[:, None, 2]) / w
            out[..., 4] = (tiles[:, None, 1] + cy[None, :] * tiles[:, None, 3]) / h
            entry.vertices = out
        return entry.vertices

    def _band_quads(self, entry: _BandEntry, sides: np.ndarray) -> int:
        quads = self._band_vertices(entry)[np.asarray(sides, dtype=bool)]
        if len(quads):
            self.band_buf.write(quads.tobytes())
        return 6 * len(quads)

    # ---------------------------------------------------------------------------------------- drawing
    def _terrain_uniforms(self, terrain: TerrainShadow | None) -> dict[str, Any]:
        """terrain_shadow.glsl's uniforms for ``terrain``, or nothing without one."""
        return {} if terrain is None else terrain.uniforms(self.ctx)

    def _depth_uniforms(self, positions: bool) -> dict[str, Any]:
        """impostor.frag's depth and normal images (units 2 and 3) and, when ``positions`` (the SHADOWS or
        GRASS_DEPTH variant), impostor.vert's uniforms for the texels' grass positions."""
        if not positions:
            return dict(atlas_depth=2, atlas_normal=3)
        distance, near, far = bake_depth_range(self.frame)
        return dict(atlas_normal=3, atlas_depth=2, bake_depth=(distance - near, far - near),
                    depth_margin=0.25 * self.data.plant_height)

    def sync_lighting(self) -> None:
        """Follow the renderer's light and the terrain's shadow.  The level-4 images are unlit (each texel is lit
        when drawn), so a new sun or sky re-bakes nothing there.  The bands' images (level 5) are captured lit:
        they are captured again once the light strays past BAND_LIGHT_TOLERANCE from the one they hold (a sun
        moving every frame, as a day's cycle moves it, re-captures the viewer's band every degree or so, not every
        frame).  A new terrain shadow re-takes each plant's share of the sun (levels 0-3) and re-captures the
        bands, whose images hold it."""
        r = self.renderer
        light = self._light()
        if self._light_key is None or not light_close(light, self._light_key):
            if self._light_key is not None:
                self.band_entries.clear()
            self._light_key = light
        terrain = r.terrain_shadow
        terrain_key = None if terrain is None else terrain.key
        if terrain_key != self._terrain_key:
            sun = 1.0 if terrain is None else terrain.visibility(self.data.placed.plant_position)
            self.plant_records[:, 7] = sun
            # a new sun alone is the light tolerance's business (above); another terrain re-captures the bands
            ground = None if terrain is None else terrain.ground_key
            if ground != self._terrain_ground and (self._terrain_ground is not None or self.band_entries):
                self.band_entries.clear()
            self._terrain_ground = ground
        self._terrain_key = terrain_key

    def prepare(self, plan: FramePlan, camera: CameraInput, viewer=None, terrain_shadow: bool = True) -> None:
        """Bake what this frame needs and is not cached yet (the LOD cache; the viewer cell's band, with the
        terrain's shadow unless ``terrain_shadow`` is off: a view that hides the terrain)."""
        self.sync_lighting()
        if len(plan.impostor_cells) or plan.band_cell is not None:
            self.ensure_impostors()
        if plan.band_cell is not None:
            self.ensure_band(plan.band_cell, camera, viewer=viewer, apothem=plan.band_apothem,
                             terrain_shadow=terrain_shadow)

    def draw(self, fbo: moderngl.Framebuffer, plan: FramePlan, view: View, camera: CameraInput,
             debug: bool, viewer=None, shadow: tuple | None = None) -> None:
        """Draw the plan into ``fbo`` (the view's colour + depth): a handful of instanced draw calls.
        ``shadow``: (the view's sun shadow map, receiver_uniforms' defines and uniforms) when it has one: the
        plants (levels 0-3) and the level-4 rectangles a caster's shadow may reach are drawn apart with the
        look-up (per vertex for the plants, per pixel at the depth the atlas holds for the rectangles)."""
        ctx = self.ctx
        self.draw_calls = 0
        fbo.use()
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
        lighting = self._lighting(view)
        fog = lighting["fog_density"] > 0.0
        terrain = self.renderer.terrain_shadow_in(view)
        # uploads first: writing a buffer that the frame's pending draws use would make the driver wait.  Level 4:
        # the rectangles a caster's shadow may reach are drawn apart, with the shadow map looked up per pixel
        shadowed = np.zeros(len(plan.impostor_cells), bool)
        if shadow is not None and len(plan.impostor_cells):
            shadowed = self._cells_reached(shadow[0], plan.impostor_cells)
        groups = ([(~shadowed, self.impostor_buf, False), (shadowed, self.impostor_shadowed_buf, True)]
                  if shadowed.any() else [(slice(None), self.impostor_buf, False)])
        rectangles = [(self._impostor_instances(plan.impostor_cells[g], plan.impostor_face[g], plan.impostor_views[g],
                                                plan.impostor_blend[g], 4, buf), buf, receiving)
                      for g, buf, receiving in groups]
        self.shadowed_rectangles = int(shadowed.sum())
        band_vertices, band = 0, None
        if plan.band_cell is not None and plan.band_sides.any():
            band = self.band_entries[self._band_key(plan.band_cell, camera, viewer, plan.band_apothem,
                                                    terrain is not None)]
            band_vertices = self._band_quads(band, plan.band_sides & band.content)
        # levels 0-3: one plant list (each level's plants nearest first, for early depth rejection), one draw
        # per level and primitive type
        counts = [len(p) for p in plan.plants]
        total = sum(counts)
        if total:
            listed = plan.plant_list if plan.plant_list is not None else np.concatenate(plan.plants)
            receives = self._receivers(shadow[0] if shadow else None, listed)
            self.shadowed_plants = 0 if receives is None else int(receives.sum())
            commands = self._upload_plants(self.instance_buf, self.plant_records, self.plant_variant, listed,
                                           counts, receives)
            shaded = terrain is not None
            if receives is None:
                passes = [(self._program("plant", debug=debug, fog=fog, terrain_shadow=shaded), {}, None)]
            else:
                if self.multi_draw:
                    self.command_buf.write(commands.tobytes())
                passes = [(self._program("plant", debug=debug, fog=fog, terrain_shadow=shaded), {}, 0),
                          (self._program("plant", debug=debug, fog=fog, terrain_shadow=shaded, shadows=shadow[1]),
                           shadow[2], 1)]
            for prog, uniforms, command_set in passes:
                set_uniforms(prog, **lighting, **self._plant_uniforms(), **uniforms)

                def set_level(level: int, prog=prog) -> None:
                    prog["debug_level"].value = level

                self._draw_plants(prog, self.instance_buf, commands, range(LEVELS), set_level if debug else None,
                                  command_set)
        # level 4 (the plan lists the rectangles nearest first; each group keeps that order)
        for count, buf, receiving in rectangles:
            if not count:
                continue
            prog = self._program("impostor", debug=debug, fog=fog, terrain_shadow=terrain is not None,
                                 shadows=shadow[1] if receiving else (), grass_depth=self.grass_depth)
            set_uniforms(prog, **{**lighting, **self._impostor_uniforms(view.view_proj, view.camera_pos, view.ortho),
                                  **self._terrain_uniforms(terrain),
                                  **self._depth_uniforms(receiving or self.grass_depth),
                                  **(shadow[2] if receiving else {})})
            self.atlas.use(0)
            self.bounds_tex.use(1)
            self.atlas_depth.use(2)
            self.atlas_normal.use(3)
            self._vao(prog, ("impostor", buf)).render(moderngl.TRIANGLE_STRIP, vertices=4, instances=count)
            self.draw_calls += 1
        # level 5
        if band_vertices:
            prog = self._program("band", debug=debug, fog=fog)
            set_uniforms(prog, **lighting, band_tex=0, band_distance=1, band_eye=tuple(float(x) for x in band.eye))
            self.band_tex.use(0)
            self.band_distance.use(1)
            self._vao(prog, ("band",)).render(moderngl.TRIANGLES, vertices=band_vertices)
            self.draw_calls += 1

    def release(self) -> None:
        if self._released:
            return
        self._released = True
        objects = [self.instance_buf, self.command_buf, self.impostor_buf, self.impostor_shadowed_buf,
                   self.bounds_tex, self.band_buf, self.atlas, self.atlas_depth, self.atlas_normal,
                   self.band_tex, self.band_distance, self.band_fbo, self.band_depth]
        objects += list(self._vaos.values())  # the programs belong to the renderer (shared between fields)
        objects += list(self.mesh_vbo.values()) + list(self.mesh_ibo.values())
        for obj in objects:
            if obj is not None:
                obj.release()


class GrassFieldFeature(RenderFeature):
    """Render feature of every GrassField: plans each view on the CPU, then one opaque pass draws it."""

    name = "grass_field"
    phase = OPAQUE

    def __init__(self, renderer: Any) -> None:
        super().__init__(renderer)
        self.fields: dict[int, FieldGpu] = {}
        self.orientations: dict[tuple[int, str], ImpostorOrientation] = {}
        self.plans: dict[tuple[int, str], FramePlan] = {}  # the last plan per (entity, view), for statistics

    def extract(self, world) -> list[FieldFrame]:
        out = []
        for entity, (transform, cfg, state) in world.query(Transform, GrassFieldConfig, GrassFieldState):
            data = ensure_placed(world, transform, cfg, state)
            out.append(FieldFrame(entity, cfg, state, data, state.max_level, state.debug_levels))
        alive = {frame.entity for frame in out}
        for entity in [e for e in self.fields if e not in alive]:  # despawned fields
            self.fields.pop(entity).release()
        for per_view in (self.orientations, self.plans):
            for key in [k for k in per_view if k[0] not in alive]:
                del per_view[key]
        return out

    def gpu(self, frame: FieldFrame) -> FieldGpu:
        """The field's GL resources; rebuilt only when what it draws changed (not for a restored copy)."""
        gpu = self.fields.get(frame.entity)
        if gpu is None or gpu.data.key != frame.data.key:
            if gpu is not None:
                gpu.release()
            gpu = FieldGpu(self.renderer, frame.cfg, frame.state, frame.data)
            self.fields[frame.entity] = gpu
            for key in [k for k in self.orientations if k[0] == frame.entity]:
                del self.orientations[key]
        return gpu

    def add_passes(self, graph, view: View, data: list[FieldFrame]) -> None:
        for frame in data or ():
            gpu = self.gpu(frame)
            camera = camera_from_view(view)
            orientation = self.orientations.get((frame.entity, view.name))
            if orientation is None:
                orientation = ImpostorOrientation(frame.data.cell_count)
                self.orientations[(frame.entity, view.name)] = orientation
            plan = plan_frame(frame.cfg, frame.data, camera, orientation, max_level=frame.max_level,
                              band_content=gpu.band_content)
            self.plans[(frame.entity, view.name)] = plan

            def setup(b):
                opaque_setup(view)(b)
                read_shadow(b, view)

            def execute(pc, gpu=gpu, plan=plan, camera=camera, debug=frame.debug):
                gpu.prepare(plan, camera, viewer=view.name,
                            terrain_shadow=self.renderer.terrain_shadow_in(view) is not None)
                fbo = self.renderer.framebuffer(pc.get(view.color), pc.get(view.depth))
                shadow = view.extra.get("shadow")
                receiving = (shadow, *receiver_uniforms(shadow, pc)) if shadow is not None else None
                gpu.draw(fbo, plan, view, camera, debug, viewer=view.name, shadow=receiving)

            graph.add_pass(f"grass_field.{frame.entity}.{view.name}", setup, execute)

    def release(self) -> None:
        for gpu in self.fields.values():
            gpu.release()
        self.fields.clear()
