"""The energy-wave render feature: additive billboards expanded on the GPU, plus a glow (bloom) pass.

Per frame, :func:`~systems.energy_wave.extract.extract_frame` packs one record per particle; they are uploaded to
an RGBA32F texture (three texels a record) and drawn as camera-facing squares with no vertex attributes, three
draws per emitter (single sprites, trails of M, bars of N); the vertex shader finds its particle and sub-sprite
from ``gl_VertexID`` (eqs. 3.7–3.9).  Each sprite is a point sprite (one vertex; ``gl_PointSize`` is the projected
side of the camera-facing quad), or, in a frame where a sprite could exceed the driver's largest point, a quad
(two triangles over four corners, an index buffer so that each corner is shaded once).  (Not instanced: llvmpipe
runs its vertex pipeline once per instance, a fixed cost that made up most of the vertex work.)  Blending is
additive (ONE, ONE), depth-tested against the scene with no depth writes, so no sorting is needed.

Passes per view, in the transparent phase (off-screen particles, Nguyen, GPU Gems 3 ch. 23: the soft sprites are
fill-rate bound, so they are drawn at half resolution):
``energy_wave.sprites.<view>``: every sprite, additively, into a half-resolution HDR buffer; occlusion is the
hardware depth test (no writes) against a half-resolution depth target that a first full-rectangle draw fills with
the view's depth (one full-size pixel per particle-buffer pixel) while clearing the colour;
``energy_wave.glow_blur_x/y.<view>``: a separable Gaussian blur of that buffer at quarter resolution (bloom), its
nine bilinear taps per axis fetched as pairs of texels where the grids line up (:func:`blur_taps`);
``energy_wave.glow_add.<view>``: glow strength × the blurred buffer, upsampled, added into the buffer;
``energy_wave.composite.<view>``: the buffer, upsampled, added onto the view's HDR colour: a colour layer
(:class:`engine.render.feature.ColorLayer`), which the view's tone map adds instead when nothing is drawn over
the wave (one read-modify-write of the full-size HDR target fewer).
The glow of a frame uses the largest ``glow`` and ``glow_radius`` among the emitters.

When every emitter drawn in a view shares one colour pair (``color``, ``core_color``), the buffers hold two
channels instead of RGB: a sprite's colour ``mix(color, core, g²) · g·I`` is ``color · g·I + (core - color) ·
g³·I``, linear in the two weights, so the buffers (rg32f) sum ``g·I`` and ``g³·I`` and the layer's matrix applies
the colours once per pixel. Half the channels of additive half-float blending per sprite fragment: table 4.3's
case 4 went from 45.4 to 37.4 ms a frame (alternating runs in one process); pictures within 1/255.

Every pass is scissored to the part of its target that can differ from zero or that a later pass reads
(:func:`pass_rects`): the sprites' projected bounds (:func:`sprite_bounds`) grown by the blur's reach and the
bilinear footprints. Outside those rectangles the full-screen passes would only have added zeros, so the image is
the same while the fill is limited to the pixels near the wave.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import moderngl
import numpy as np

from engine.render.feature import TRANSPARENT, ColorLayer, RenderFeature, View
from engine.render.graph import TextureDesc
from engine.render.passes import add_color_layer, add_texture, set_uniforms

from .extract import BAR, RECORD_FLOATS, SINGLE, TRAIL, FrameData, extract_frame
from .simulate import bar_sizes, trail_sizes

if TYPE_CHECKING:
    from engine.render.renderer import Renderer
    from engine.world import World

SHADERS = Path(__file__).parent / "shaders"
RECORDS_PER_ROW = 1024
PARTICLE_DOWNSCALE = 2  # sprites are drawn at half the view's resolution (off-screen particles), then upsampled
GLOW_DOWNSCALE = 4
# The particle and glow buffers' formats: RGB sums of the sprites' colours, or, when every emitter drawn in the view
# shares one colour pair (colour and core colour), the two weights that pair's colours multiply (particles.frag
# TWO_CHANNEL). Two channels of additive blending per fragment instead of four: the sprite pass of table 4.3's
# case 4 went from 22.4 to 17.7 ms (rg16f; rg32f 16.5) in alternating runs on llvmpipe. Single floats, not half
# floats: llvmpipe converts every half-float texel it blends, fetches or filters, and the whole case-4 frame
# measured 33.9 -> 30.8, 31.7 -> 30.8 and 43.4 -> 41.8 ms (rg16f -> rg32f; rgba16f -> rgba32f 45.6 -> 43.9 and
# 43.2 -> 42.1 ms), alternating blocks of frames in one process; 1.8 MB instead of 0.9 MB at 1280 x 720.
COLOR_FORMAT, PAIR_FORMAT = "rgba32f", "rg32f"
QUAD_INDICES = np.array([0, 1, 2, 2, 1, 3], np.uint32)  # a sprite's two triangles over its four corners
UV = tuple[float, float, float, float]  # (u0, v0, u1, v1) in a view's texture coordinates


def radial_gradient(r2: np.ndarray) -> np.ndarray:
    """The sprite's falloff at squared distance ``r2`` from its centre (sprite radius 1): (1 - r²)² · exp(-3 r²)
    inside, 0 outside; ``particles.frag`` evaluates the same formula per fragment."""
    r2 = np.asarray(r2, dtype=np.float64)
    return np.where(r2 < 1.0, (1.0 - r2) ** 2 * np.exp(-3.0 * r2), 0.0)


def _sprite_ends(data: FrameData, view_proj: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Clip coordinates of the end points of every sprite run (a single sprite, a trail's P0 and P1, a bar's two
    tips) and the largest sprite half-size of each run's emitter (eq. 3.9, trail scale); None without sprites."""
    m = view_proj.astype(np.float64)
    clips, sizes = [], []
    for emitter in data.emitters:
        cfg = emitter.config
        records = data.records[emitter.first: emitter.first + emitter.total]
        single, trail, bar = emitter.counts
        size = cfg.particle_size * max(1.0, float(trail_sizes(cfg.trail_textures, cfg.trail_end_scale).max()),
                                       float(bar_sizes(cfg.splash_samples, cfg.splash_roundness).max()))
        centre = records[:, 0:3] @ m[:, :3].T + m[:, 3]  # clip coordinates of the particles
        ends = [centre]
        if trail:
            ends.append(records[single: single + trail, 4:7] @ m[:, :3].T + m[:, 3])  # P0, the trail's other end
        if bar:
            reach = cfg.bar_spacing * cfg.particle_size * (cfg.splash_samples - 1)
            tips = records[single + trail:, 8:11] @ (m[:, :3].T * reach)
            ends += [centre[single + trail:] + tips, centre[single + trail:] - tips]
        clips += ends
        sizes += [np.full(len(e), size) for e in ends]
    if not clips:
        return None
    return np.concatenate(clips), np.concatenate(sizes)


def sprite_bounds(data: FrameData, view_proj: np.ndarray, right: np.ndarray, up: np.ndarray,
                  ends: tuple | None = ...) -> UV | None:
    """Texture-coordinate bounds of every sprite of the frame in a view; (0, 0, 1, 1) when one reaches behind the
    camera. The sprites of a trail (eq. 3.7) or a bar (eq. 3.8) lie on the segment between two end points, each
    within the camera-facing square of the emitter's largest sprite size (eq. 3.9, trail scale); the square is
    planar and convex and projection keeps convex hulls, so the projected corners of the ends' squares bound them.
    ``ends``: :func:`_sprite_ends` of this view when the caller has it."""
    if ends is ...:
        ends = _sprite_ends(data, view_proj)
    if ends is None:
        return None
    clip, size = ends
    m = view_proj.astype(np.float64)
    dx = np.abs(m[:, :3] @ np.asarray(right, np.float64))  # clip-space change along the square's sides
    dy = np.abs(m[:, :3] @ np.asarray(up, np.float64))
    reach = dx + dy  # per unit of size: a corner's clip coordinates lie within centre ± reach·size
    w_lo = clip[:, 3] - reach[3] * size  # 0 for a camera-facing square but for rounding
    w_hi = clip[:, 3] + reach[3] * size
    if w_lo.min() <= 1e-6:
        return 0.0, 0.0, 1.0, 1.0
    bounds = []
    for axis in (0, 1):  # x / w over the box [x ± reach·size] × [w_lo, w_hi] (w > 0): extremes at its corners
        low, high = clip[:, axis] - reach[axis] * size, clip[:, axis] + reach[axis] * size
        bounds.append((min((low / w_lo).min(), (low / w_hi).min()), max((high / w_lo).max(), (high / w_hi).max())))
    (x0, x1), (y0, y1) = bounds
    return float(x0 * 0.5 + 0.5), float(y0 * 0.5 + 0.5), float(x1 * 0.5 + 0.5), float(y1 * 0.5 + 0.5)


def largest_sprite_pixels(data: FrameData, view_proj: np.ndarray, pixels: float, ends: tuple | None = ...) -> float:
    """An upper bound of the side, in pixels of a target ``pixels`` high, of the largest sprite of the frame
    (``pixels`` times ``view_proj[1, 1]`` is the side of a sprite of half-size 1 at w = 1); inf when a sprite's end
    lies at or behind the camera.  A trail's or a bar's sprites lie between its ends, where 1 / w is largest.
    ``ends``: :func:`_sprite_ends` of this view when the caller has it."""
    if ends is ...:
        ends = _sprite_ends(data, view_proj)
    if ends is None:
        return 0.0
    clip, size = ends
    w = clip[:, 3]
    if w.min() <= 1e-6:
        return math.inf
    return float((size / w).max() * abs(float(view_proj[1, 1])) * pixels)


GAUSS_9 = (0.2270270270, 0.1945945946, 0.1216216216, 0.0540540541, 0.0162162162)  # glow_blur.frag's weights, |j|


@lru_cache(maxsize=32)
def blur_taps(radius: float, source: int, target: int) -> tuple[np.ndarray, np.ndarray]:
    """The bilinear fetches of one blur direction (glow_blur.frag): offsets from the output pixel's centre in
    source texels, and weights.  The blur is nine taps j = -4..4 at ``j · radius / 4`` target texels with weights
    GAUSS_9, each filtered bilinearly.  When ``source`` is ``target`` or ``2 · target`` texels long, the output
    pixels' centres all have the same phase in the source's texel grid (half way between texel centres, or on
    one), so the nine taps add up to one discrete kernel over a few source texels; pairs of adjacent texels of
    it are fetched together, bilinearly at the point that splits them by their weights (Rákos 2010's "linear
    sampling"), which gives the same sum with about half the fetches.  Otherwise, or when pairing saves
    nothing, the nine taps themselves.  Cached: the arrays returned are shared, read them only."""
    step = radius / 4.0 * source / target  # tap spacing in source texels
    taps = np.arange(-4, 5) * step
    weights = np.array([GAUSS_9[abs(j)] for j in range(-4, 5)])
    ratio = source / target
    if ratio not in (1.0, 2.0):
        return taps, weights
    phase = 0.5 if ratio == 2.0 else 0.0  # the output centre, past the source texel centre before it
    kernel: dict[int, float] = {}
    for t, w in zip(phase + taps, weights):  # each tap's bilinear weights on the source texels (relative)
        k = math.floor(t)
        f = t - k
        kernel[k] = kernel.get(k, 0.0) + (1.0 - f) * w
        if f > 0.0:
            kernel[k + 1] = kernel.get(k + 1, 0.0) + f * w
    texels = sorted(k for k, w in kernel.items() if w > 0.0)
    offsets, sums, i = [], [], 0
    while i < len(texels):
        k = texels[i]
        if i + 1 < len(texels) and texels[i + 1] == k + 1:  # two adjacent texels: one fetch between them
            w0, w1 = kernel[k], kernel[k + 1]
            offsets.append(k + w1 / (w0 + w1) - phase)
            sums.append(w0 + w1)
            i += 2
        else:
            offsets.append(k - phase)
            sums.append(kernel[k])
            i += 1
    if len(offsets) >= len(taps):
        return taps, weights
    return np.array(offsets), np.array(sums)


def _grow(rect: UV, du: float, dv: float) -> UV:
    return rect[0] - du, rect[1] - dv, rect[2] + du, rect[3] + dv


def _union(a: UV, b: UV) -> UV:
    return min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])


def pixel_rect(rect: UV, width: int, height: int) -> tuple[int, int, int, int]:
    """(x, y, w, h) pixels of a ``width`` × ``height`` target whose centres can lie in ``rect`` (clamped)."""
    x0 = min(max(math.floor(rect[0] * width), 0), width)
    y0 = min(max(math.floor(rect[1] * height), 0), height)
    x1 = min(max(math.ceil(rect[2] * width), x0), width)
    y1 = min(max(math.ceil(rect[3] * height), y0), height)
    return x0, y0, x1 - x0, y1 - y0


def pass_rects(bounds: UV, particles: tuple[int, int], glow_size: tuple[int, int], radius: float,
               glow: bool) -> dict[str, UV]:
    """What each pass must write so that the image equals the unscissored passes' (texture coordinates).

    ``composite``: where the particle buffer or the glow can be non-zero (sprites grown by a particle texel, the
    blur's reach of ``radius`` quarter texels per axis and bilinear footprints); ``blur_y``: what the composite
    samples; ``blur_x``: what ``blur_y`` samples; ``particles``: what ``blur_x`` and the composite sample, cleared
    (and given the scene's depth) before the sprites are drawn. Margins of two texels per bilinear read.
    """
    th = 1.0 / particles[0], 1.0 / particles[1]
    sprites = _grow(bounds, th[0], th[1])
    if not glow:
        composite = _grow(sprites, 2 * th[0], 2 * th[1])
        return dict(composite=composite, particles=_grow(composite, 2 * th[0], 2 * th[1]))
    tq = 1.0 / glow_size[0], 1.0 / glow_size[1]
    reach = radius * tq[0], radius * tq[1]  # 4 taps of radius / 4 texels
    composite = _grow(sprites, reach[0] + 3 * tq[0] + th[0], reach[1] + 3 * tq[1] + th[1])
    blur_y = _grow(composite, 2 * tq[0], 2 * tq[1])
    blur_x = _grow(blur_y, 2 * tq[0], reach[1] + 2 * tq[1])
    cleared = _union(_grow(blur_x, reach[0] + 2 * tq[0], 2 * tq[1]), _grow(composite, 2 * th[0], 2 * th[1]))
    return dict(composite=composite, blur_y=blur_y, blur_x=blur_x, particles=cleared)


@dataclass
class _KeptDepth:
    """A camera's half-resolution depth copy and the static layer key it was copied from."""

    texture: moderngl.Texture
    key: object = None  # the key the copy holds (None: not copied yet)


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
        self._indices: moderngl.Buffer | None = None
        self._index_sprites = 0  # sprites the index buffer covers
        self._fullscreen: dict[str, moderngl.VertexArray] = {}
        self._points: dict[tuple[str, ...], moderngl.VertexArray] = {}
        self._quads: dict[tuple[str, ...], moderngl.VertexArray] = {}
        # sprites as point sprites (one vertex each: llvmpipe's vertex stage and triangle setup ran 4 vertices and
        # 2 triangles a sprite, half the sprite pass in table 4.3's case 4) unless a sprite would exceed the
        # largest point size the driver rasterises, where the frame falls back to two triangles a sprite
        self.point_sprites = True
        self.max_point_size = float(renderer.ctx.info.get("GL_POINT_SIZE_RANGE", (1.0, 1.0))[1])
        self.last_sprite_path = ""  # "points" or "quads": the last view's sprite draw (tests, profiling)
        # two-channel buffers when the view's emitters share one colour pair (COLOR_FORMAT, PAIR_FORMAT)
        self.colour_pairs = True
        self.last_channels = 0  # 2 or 3: the last view's buffers (tests, profiling)
        # the half-resolution depth kept per camera while its view's depth is a restored static layer untouched
        # (Renderer.static_depth_key): the same key is the same depth, so the copy is made once and the later
        # frames clear the colour only (off: the copy every frame; A/B, tests)
        self.keep_half_depth = True
        self._half_depth: dict[int, _KeptDepth] = {}
        self.depth_copies = 0  # half-resolution depth copies drawn (tests)

    # ------------------------------------------------------------------------------------------ extraction
    def extract(self, world: World) -> FrameData:
        from engine.render.components import Camera

        cameras = {entity for entity, _ in world.query(Camera)}
        for camera in [c for c in self._half_depth if c and c not in cameras]:  # a camera gone: free its depth
            self.release_texture(self._half_depth.pop(camera).texture)
        return extract_frame(world)

    # ------------------------------------------------------------------------------------------- GL objects
    def _program(self, name: str, defines: tuple[str, ...] = ()) -> moderngl.Program:
        return self.renderer.load_program(SHADERS, name, defines)

    def _cached_vao(self, cache: dict, key, prog: moderngl.Program, **kwargs) -> moderngl.VertexArray:
        """``cache[key]``: a buffer-less vertex array of ``prog`` (``kwargs``: its index buffer), remade when the
        program changed (F5 reloads shaders)."""
        vao = cache.get(key)
        if vao is None or vao.program is not prog:
            if vao is not None:
                vao.release()
            vao = cache[key] = self.ctx.vertex_array(prog, [], **kwargs)
        return vao

    def _point_vao(self, defines: tuple[str, ...]) -> moderngl.VertexArray:
        """The point-sprite variant: one vertex a sprite, its square rasterised by the driver (gl_PointSize)."""
        return self._cached_vao(self._points, defines, self._program("particles", ("POINTS",) + defines))

    def _sprite_vao(self, sprites: int, defines: tuple[str, ...]) -> moderngl.VertexArray:
        """The sprites' vertex array: no attributes (corners from ``gl_VertexID``), an index buffer of two triangles
        per sprite over its four corners, so llvmpipe shades each corner once (6 indices, 4 vertices)."""
        if self._indices is None or sprites > self._index_sprites:
            for obj in [self._indices, *self._quads.values()]:
                if obj is not None:
                    obj.release()
            self._quads.clear()
            self._index_sprites = 1 << max(10, (sprites - 1).bit_length())
            corners = 4 * np.arange(self._index_sprites, dtype=np.uint32)[:, None] + QUAD_INDICES
            self._indices = self.ctx.buffer(corners.tobytes())
        return self._cached_vao(self._quads, defines, self._program("particles", defines),
                                index_buffer=self._indices, index_element_size=4)

    def _fullscreen_vao(self, name: str) -> moderngl.VertexArray:
        return self._cached_vao(self._fullscreen, name, self._program(name))

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
    def _draw_sprites(self, view: View, data: FrameData, target_height: int, largest: float,
                      defines: tuple[str, ...]) -> None:
        """Every sprite, additively, into the bound half-resolution target ``target_height`` pixels high: as
        point sprites (``particles.vert`` POINTS: the square of side ``gl_PointSize`` = the quad's projected side)
        or, when the ``largest`` sprite (:func:`largest_sprite_pixels`) would exceed the driver's largest point, as
        quads of two triangles. ``defines``: ("TWO_CHANNEL",) for a colour pair's weights (:meth:`colour_pair`)."""
        points = self.point_sprites and largest <= self.max_point_size
        self.last_sprite_path = "points" if points else "quads"
        if points:
            vao = self._point_vao(defines)
            self.ctx.enable(moderngl.PROGRAM_POINT_SIZE)
            set_uniforms(vao.program, point_scale=float(view.proj[1, 1]) * target_height)
            primitive, per_sprite = moderngl.POINTS, 1
        else:
            vao = self._sprite_vao(max(e.total * max(1, e.config.trail_textures, e.config.splash_samples)
                                       for e in data.emitters), defines)
            primitive, per_sprite = moderngl.TRIANGLES, len(QUAD_INDICES)
        prog = vao.program
        self._records.use(0)
        view_m = view.view.astype(np.float64)
        set_uniforms(prog, records=0, records_per_row=RECORDS_PER_ROW,
             camera_right=tuple(map(float, view_m[0, :3])), camera_up=tuple(map(float, view_m[1, :3])))
        prog["view_proj"].write(view.view_proj.T.astype(np.float32).tobytes())
        for emitter in data.emitters:
            cfg = emitter.config
            if cfg.intensity <= 0.0:
                continue
            set_uniforms(prog, size=cfg.particle_size, spacing=cfg.bar_spacing * cfg.particle_size,
                 roundness=cfg.splash_roundness, trail_end=cfg.trail_end_scale, color=tuple(cfg.color),
                 core_color=tuple(cfg.core_color), intensity=cfg.intensity)
            first = emitter.first
            groups = ((SINGLE, 0, 1), (TRAIL, 1, cfg.trail_textures), (BAR, 2, cfg.splash_samples))
            for group, mode, sprites in groups:  # three draws per emitter, whatever M and N
                count = emitter.counts[group]
                if count:
                    set_uniforms(prog, first=first, mode=mode, sprites=sprites)
                    vao.render(primitive, vertices=per_sprite * count * sprites)
                first += count
        if points:
            self.ctx.disable(moderngl.PROGRAM_POINT_SIZE)

    def colour_pair(self, data: FrameData) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
        """The (colour, core colour) every emitter drawn shares, or None when they differ (or the switch
        ``colour_pairs`` is off): the buffers then hold RGB."""
        pairs = {(tuple(map(float, e.config.color)), tuple(map(float, e.config.core_color)))
                 for e in data.emitters if e.config.intensity > 0.0}
        return next(iter(pairs)) if self.colour_pairs and len(pairs) == 1 else None

    def add_passes(self, graph, view: View, data: FrameData) -> None:
        if data is None or not data.emitters or len(data.records) == 0:
            return  # nothing alive: no passes, no full-screen composite
        ctx = self.ctx
        pair = self.colour_pair(data)
        defines = ("TWO_CHANNEL",) if pair is not None else ()
        fmt = PAIR_FORMAT if pair is not None else COLOR_FORMAT
        self.last_channels = 2 if pair is not None else 3
        size = (max(1, view.width // PARTICLE_DOWNSCALE), max(1, view.height // PARTICLE_DOWNSCALE))
        glow_size = (max(1, view.width // GLOW_DOWNSCALE), max(1, view.height // GLOW_DOWNSCALE))
        glow = max(e.config.glow for e in data.emitters)
        radius = max(e.config.glow_radius for e in data.emitters)
        view_m = view.view.astype(np.float64)
        ends = _sprite_ends(data, view.view_proj)  # shared by the bounds and the point-size check
        bounds = sprite_bounds(data, view.view_proj, view_m[0, :3], view_m[1, :3], ends)
        largest = largest_sprite_pixels(data, view.view_proj, size[1], ends)
        rects = pass_rects(bounds, size, glow_size, radius, glow > 0.0)
        if 0 in pixel_rect(rects["composite"], view.width, view.height)[2:]:
            return  # every sprite and its glow off screen: nothing reaches the image
        h: dict[str, object] = {}

        depth_key = self.renderer.static_depth_key(view) if self.keep_half_depth else None
        kept = self._kept_depth(view, size, depth_key)

        def sprites_setup(b):
            b.read(view.depth)
            h["particles"] = b.write(b.create(f"energy_wave.{view.name}.particles",
                                              TextureDesc(size[0], size[1], fmt)))
            if kept is None:
                h["depth"] = b.write(b.create(f"energy_wave.{view.name}.depth",
                                              TextureDesc(size[0], size[1], "depth24")))

        def sprites_execute(pc):
            self._upload(data)
            fbo = self.renderer.framebuffer(pc.get(h["particles"]), kept.texture if kept else pc.get(h["depth"]))
            copy = kept is None or kept.key != depth_key
            # the depth copy clears the colour too, in the particle rectangle (a scissored clear is slow on
            # llvmpipe); the whole buffer when the copy is kept, since later frames may draw elsewhere in it
            fbo.scissor = pixel_rect(rects["particles"], *size) if kept is None else None
            fbo.depth_mask = copy
            fbo.use()
            depth = pc.get(view.depth)
            compare = depth.compare_func
            depth.compare_func = ""  # read depth values, not shadow comparisons
            depth.use(2)
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.BLEND)
            try:
                if copy:
                    ctx.depth_func = "1"  # colour 0 and the view's depth
                    prepare = self._fullscreen_vao("depth_copy")
                    set_uniforms(prepare.program, scene_depth=2, depth_scale=float(PARTICLE_DOWNSCALE))
                    prepare.render(moderngl.TRIANGLES, vertices=3)
                    self.depth_copies += 1
                    if kept is not None:
                        kept.key = depth_key
                else:  # the kept depth is this frame's: the colour cleared, whole (queued like a draw)
                    fbo.clear(0.0, 0.0, 0.0, 0.0)
                fbo.scissor = pixel_rect(rects["particles"], *size)
                ctx.depth_func = "<="  # the old in-shader test kept fragments with z <= scene depth
                fbo.depth_mask = False
                fbo.use()
                ctx.enable(moderngl.BLEND)
                ctx.blend_func = moderngl.ONE, moderngl.ONE
                self._draw_sprites(view, data, size[1], largest, defines)
            finally:
                depth.compare_func = compare
                ctx.depth_func = "<"
                fbo.depth_mask = True
                fbo.scissor = None
                ctx.blend_func = moderngl.DEFAULT_BLENDING
                ctx.disable(moderngl.BLEND | moderngl.DEPTH_TEST)

        def blur(src_key: str, dst_key: str, axis: int):
            def setup(b):
                b.read(h[src_key])
                h[dst_key] = b.write(b.create(f"energy_wave.{view.name}.{dst_key}",
                                              TextureDesc(glow_size[0], glow_size[1], fmt)))

            def execute(pc):
                fbo = self.renderer.framebuffer(pc.get(h[dst_key]))
                fbo.scissor = pixel_rect(rects[dst_key], *glow_size)
                fbo.use()
                ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
                source = pc.get(h[src_key])
                source.use(0)
                texel = [0.0, 0.0]
                texel[axis] = 1.0 / source.size[axis]
                offsets, weights = blur_taps(radius, source.size[axis], glow_size[axis])
                taps = f"TAPS {len(offsets)}"
                vao = self._cached_vao(self._fullscreen, ("glow_blur", taps), self._program("glow_blur", (taps,)))
                prog = vao.program
                set_uniforms(prog, source=0, axis_uv=tuple(texel))
                prog["offsets"].write(offsets.astype(np.float32).tobytes())
                prog["weights"].write(weights.astype(np.float32).tobytes())
                try:
                    vao.render(moderngl.TRIANGLES, vertices=3)
                finally:
                    fbo.scissor = None

            return setup, execute

        if pair is None:
            matrix = np.eye(3)
        else:  # the colour pair's weights (particles.frag TWO_CHANNEL): colour · Σ g·I + (core - colour) · Σ g³·I
            colour, core = np.array(pair[0]), np.array(pair[1])
            matrix = np.column_stack([colour, core - colour, np.zeros(3)])

        def glow_setup(b):
            b.read(h["blur_y"])
            h["particles"] = b.write(h["particles"])

        def glow_execute(pc):  # the bloom added into the particle buffer: the composite then samples one texture
            add_texture(self.renderer, pc.get(h["particles"]), pc.get(h["blur_y"]), float(glow) * np.eye(3),
                        pixel_rect(_grow(rects["composite"], 2.0 / size[0], 2.0 / size[1]), *size))

        graph.add_pass(f"energy_wave.sprites.{view.name}", sprites_setup, sprites_execute)
        if glow > 0.0:
            graph.add_pass(f"energy_wave.glow_blur_x.{view.name}", *blur("particles", "blur_x", 0))
            graph.add_pass(f"energy_wave.glow_blur_y.{view.name}", *blur("blur_x", "blur_y", 1))
            graph.add_pass(f"energy_wave.glow_add.{view.name}", glow_setup, glow_execute)
        add_color_layer(graph, self.renderer, f"energy_wave.composite.{view.name}", view,
                        ColorLayer(h["particles"], matrix, pixel_rect(rects["composite"], view.width, view.height)))

    def _kept_depth(self, view: View, size: tuple[int, int], key) -> _KeptDepth | None:
        """The half-resolution depth kept for ``view``'s camera when its depth is a restored static layer
        untouched (``key``: :meth:`Renderer.static_depth_key`, None when not or when :attr:`keep_half_depth` is
        off); None otherwise, and what was kept for the camera is released."""
        kept = self._half_depth.get(view.camera_entity)
        if kept is not None and (key is None or kept.texture.size != size):
            self.release_texture(self._half_depth.pop(view.camera_entity).texture)
            kept = None
        if key is None:
            return None
        if kept is None:
            kept = self._half_depth[view.camera_entity] = _KeptDepth(self.ctx.depth_texture(size))
        return kept

    def release(self) -> None:
        for obj in (self._records, self._indices, *self._points.values(), *self._quads.values(),
                    *self._fullscreen.values()):
            if obj is not None:
                obj.release()
        for kept in self._half_depth.values():
            self.release_texture(kept.texture)  # drawn into through renderer.framebuffer
        self._half_depth.clear()
        self._records = self._indices = None
        self._index_sprites = 0
        self._points.clear()
        self._quads.clear()
        self._fullscreen.clear()
