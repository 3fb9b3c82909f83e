"""Dust devil rendering: particle-based volume rendering (PBVR, 2.3 of seeds/004) and the field markers (4).

PBVR per view and dust devil, as passes of the render graph.  Per repeat r = 0..R-1, K random pseudo-particles
around every real particle are drawn as opaque points with the scene's depth test; each repeat is one opaque
ensemble image (a pixel is covered or not, whatever number of pseudo-particles land on it), and the R images are
averaged: colour = colour_sand * n / R + scene * (1 - n / R), n the number of repeats covering the pixel.

The pseudo-particles' offsets come from a table of points uniform in the unit ball, drawn once from the engine's
seeded random streams (:func:`ball_offsets`) and bound as a uniform block; particle i's samples this frame are
consecutive table entries from a hashed start (shaders/pbvr_sample.glsl; :func:`sample_indices` in numpy).

Two implementations of the same ensemble (same pseudo-particles, same coverage counts n):

* **scatter** (GL 4.3 compute shaders, else GL 4.2 image load/store in the vertex stage; the first the context
  compiles, probed once and logged):
  a persistent coverage image of one 32-bit word per pixel (two for R > 32), all zero between frames;
  ``pbvr_accumulate`` has each pseudo-particle test the pixels of its point against the view's depth and OR bit r
  into their words: one compute invocation per real particle, which projects it once and draws its R x K
  pseudo-particles (shaders/pbvr_scatter.comp), or one draw of N x (R x K) vertices with rasterisation off
  (shaders/pbvr_scatter.vert);
  ``pbvr_resolve`` counts the bits and composites over the view, inside the screen rectangle the particle cloud
  can reach, and zeroes the words it read (so it writes the coverage image too; no clear pass).  A software
  rasteriser spends most of a point's cost on setting up and shading its pixel block; here a pseudo-particle
  costs a few dozen shader instructions, and a compute dispatch runs on all of the driver's worker threads
  (llvmpipe runs the vertex stage on the calling thread alone).
* **slab** (GL 3.3): ``pbvr_clear`` clears an rgba16f accumulation target and a depth buffer;
  ``pbvr_accumulate`` draws the R repeats as points, repeat r at the depth of its own slab, additively blended
  (rgb += colour, a += 1) with the depth test GL_LESS, which counts a pixel once per repeat;
  ``pbvr_resolve`` divides by R and composites.

R is ``repeats``, or ``drag_repeats`` (at most ``repeats``) while the field is being dragged.  With PBVR off the real particles are
drawn as opaque points instead.  The markers (red spheres at the box's 8 corners and centre) are lit instanced
spheres drawn with the engine's mesh shader.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import moderngl
import numpy as np

from components.dust_devil import DustDevilConfig, DustDevilState
from engine.render.feature import OPAQUE, TRANSPARENT, RenderFeature, View, write_view_color
from engine.render.graph import TextureDesc
from engine.render.passes import SHADERS as ENGINE_SHADERS
from engine.render.passes import lighting_uniforms, opaque_setup, primitive, set_uniforms
from engine.rng import derive_generator
from engine.spatial import Transform
from systems.dust_devil.simulate import marker_points, world_positions

SHADERS = Path(__file__).parent / "shaders"
LOG = logging.getLogger(__name__)
MARKER_COLOR = (0.9, 0.06, 0.04)
MARKER_SEGMENTS = (8, 12)  # stacks, slices: 192 triangles a marker (the engine's sphere has 480); they stay small


@dataclass
class DevilFrame:
    """What one dust devil draws this frame (copied out of the world in render-extract)."""

    entity: int
    positions: np.ndarray  # (N, 3) float32, world space
    color: tuple[float, float, float]
    pbvr: bool
    sub_particles: int  # K
    repeats: int  # R this frame (DustDevilConfig.dragging_repeats while dragging)
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
                              cfg.sub_particles, cfg.dragging_repeats if dragging else cfg.repeats,
                              cfg.sub_particle_radius, cfg.point_size, dragging))
    return out


GL_R32UI = 0x8236  # the coverage words: 32-bit unsigned integers, one per pixel and word
MAX_SCATTER_REPEATS = 64  # two coverage words per pixel
COMPUTE_GROUP = 64  # invocations per work group of pbvr_scatter.comp


BALL_OFFSETS = 1024  # entries of the pseudo-particle offset table (pbvr_sample.glsl's BALL_OFFSETS)
BALL_STREAM = "dust_devil.pbvr_offsets"  # the random stream the table is drawn from
BALL_BINDING = 0  # uniform block binding point of the table


def ball_offsets(seed: int, count: int = BALL_OFFSETS) -> np.ndarray:
    """The pseudo-particle offset table (count, 4) float32: xyz independent and uniform in the unit ball (2.3),
    w = 0.  Drawn from the stream ``BALL_STREAM`` of the scene's seed, derived as the engine's streams are
    (:func:`engine.rng.derive_generator`) but not registered in the world: rendering leaves the state hash alone.

    A uniform point in the ball: a uniform direction (a normalised Gaussian vector) at radius u^(1/3), u uniform
    in [0, 1) (the volume inside radius ρ is ρ³)."""
    rng = derive_generator(seed, BALL_STREAM)
    direction = rng.standard_normal((count, 3))
    radius = np.cbrt(rng.random(count))
    out = np.zeros((count, 4), np.float32)
    out[:, :3] = direction * (radius / np.linalg.norm(direction, axis=1))[:, None]
    return out


def pcg_hash(v: np.ndarray | int) -> np.ndarray:
    """pbvr_sample.glsl's ``pcg_hash`` on uint32 (Jarzynski & Olano 2020, PCG with one word of state)."""
    with np.errstate(over="ignore"):
        state = np.asarray(v, np.uint32) * np.uint32(747796405) + np.uint32(2891336453)
        word = ((state >> ((state >> np.uint32(28)) + np.uint32(4))) ^ state) * np.uint32(277803737)
        return (word >> np.uint32(22)) ^ word


def frame_key(tick: int, drawn: int = 0) -> int:
    """The shaders' ``frame_key`` uniform of a frame: a hash of the world's tick it shows and of the frames drawn
    at that tick before it (``drawn``), so every frame draws a new ensemble (a paused game's too) and a frame is a
    function of the state it shows: a run restored from a snapshot, or another frame rate, draws the same picture
    at the same tick."""
    with np.errstate(over="ignore"):
        return int(pcg_hash(np.uint32(tick % 2**32) ^ pcg_hash(np.uint32(drawn % 2**32))))


def sample_indices(particles: int, samples: int, key: int) -> np.ndarray:
    """Table entries (particles, samples) of the pseudo-particles ``r * K + k`` of particles 0..N-1 in the frame
    with ``frame_key`` ``key`` (pbvr_sample.glsl: consecutive entries from a hashed start per particle)."""
    with np.errstate(over="ignore"):
        start = pcg_hash(np.arange(particles, dtype=np.uint32) + np.uint32(key))
        return (start[:, None] + np.arange(samples, dtype=np.uint32)) & np.uint32(BALL_OFFSETS - 1)


def slab_depth(r: int, repeats: int) -> float:
    """NDC depth of repeat r's slab: strictly decreasing in r, so each repeat passes GL_LESS once per pixel."""
    return 1.0 - 2.0 * (r + 1) / (repeats + 1)


def coverage_words(repeats: int) -> int:
    """32-bit coverage words per pixel for R repeats (bit r of word r // 32)."""
    return (repeats + 31) // 32


def screen_rect(positions: np.ndarray, view_proj: np.ndarray, width: int, height: int, radius: float,
                 point_size: float) -> tuple[int, int, int, int] | None:
    """Pixels (x, y, w, h) that pseudo-particles within ``radius`` of ``positions`` can cover, or None when none
    is on screen; the whole view when a ball reaches the camera plane.

    A point p + d with |d| <= radius projects within (radius (|row_x| + |x/w| |row_w|)) / (w - radius |row_w|)
    of p's NDC x (row_x, row_w: the xyz parts of view_proj's rows), likewise for y; grown by half a point and a
    pixel for the points' squares and rounding."""
    if not len(positions):
        return None
    m = view_proj.astype(np.float64)
    rows = m[[0, 1, 3]]  # clip x, y, w (z is not needed): one (N, 3) product, each axis then as a column
    clip = positions.astype(np.float64) @ rows[:, :3].T
    clip += rows[:, 3]
    w = clip[:, 2]
    reach_w = radius * np.linalg.norm(m[3, :3])
    near = w - reach_w
    if near.min() <= 1e-9:
        return 0, 0, width, height
    inv_near = 1.0 / near
    reach = radius * np.linalg.norm(m[:2, :3], axis=1)
    pixels = 0.5 * point_size + 1.0
    first, last = [], []
    for axis, size in enumerate((width, height)):
        ndc = clip[:, axis] / w
        margin = (np.abs(ndc) * reach_w + reach[axis]) * inv_near
        low, high = float((ndc - margin).min()), float((ndc + margin).max())
        first.append(min(max(math.floor((low * 0.5 + 0.5) * size - pixels), 0), size))
        last.append(min(max(math.ceil((high * 0.5 + 0.5) * size + pixels), 0), size))
    if last[0] <= first[0] or last[1] <= first[1]:
        return None
    return first[0], first[1], last[0] - first[0], last[1] - first[1]


class DustDevilParticles(RenderFeature):
    """PBVR (or plain points) for every dust devil."""

    name = "dust_devil"
    phase = TRANSPARENT

    def __init__(self, renderer) -> None:
        super().__init__(renderer)
        self._buffers: dict[int, tuple[moderngl.Buffer, dict[str, moderngl.VertexArray]]] = {}
        self._uploaded: dict[int, int] = {}  # entity -> frame index of the last upload
        self.declared_repeats: dict[tuple[int, str], int] = {}  # (entity, view) -> R of the last declared frame
        self.scatter: bool | None = None  # the coverage-word scatter path; None: probed at the first PBVR frame
        self.compute = False  # the scatter as a compute shader (GL 4.3); else in the vertex stage (GL 4.2)
        self._resolve: dict[tuple[str, str], moderngl.VertexArray] = {}
        self._seed = 0  # the scene's random seed (the offset table is drawn from it)
        self._ball: tuple[int, moderngl.Buffer] | None = None  # (seed, uniform buffer of ball_offsets(seed))
        # (entity, view) -> (size, texture): the persistent coverage words, zero between frames
        self._coverage: dict[tuple[int, str], tuple[tuple[int, int], moderngl.Texture]] = {}
        self._unresolved: set[tuple[int, str]] = set()  # coverage scattered into but not resolved (zeroed) yet
        self._tick, self._drawn_at_tick = -1, 0  # the tick extracted last, and the frames extracted at it before

    @property
    def frame_key(self) -> int:
        """This frame's ``frame_key`` (:func:`frame_key` of the tick extracted and the frames drawn at it before)."""
        return frame_key(self._tick, self._drawn_at_tick)

    def extract(self, world) -> list[DevilFrame]:
        self._seed = int(world.random.seed)
        tick = int(world.tick)
        self._drawn_at_tick = self._drawn_at_tick + 1 if tick == self._tick else 0
        self._tick = tick
        devils = extract_devils(world)
        entities = {d.entity for d in devils}
        for key in [k for k in self._coverage if k[0] not in entities]:  # a dust devil gone: free its images
            self.release_texture(self._coverage.pop(key)[1])
            self._unresolved.discard(key)
        for entity in [e for e in self._buffers if e not in entities]:  # and its particle buffer
            buf, vaos = self._buffers.pop(entity)
            for vao in vaos.values():
                vao.release()
            buf.release()
            self._uploaded.pop(entity, None)
        for key in [k for k in self.declared_repeats if k[0] not in entities]:
            del self.declared_repeats[key]
        return devils

    # -------------------------------------------------------------------------- GL objects
    def _vao(self, devil: DevilFrame, program: str, defines: tuple[str, ...] = ()) -> moderngl.VertexArray:
        """The VAO of ``shaders/<program>`` (the renderer's variant ``defines``) over the devil's particle buffer,
        uploaded once per frame."""
        buf = self._particle_buffer(devil)
        vaos = self._buffers[devil.entity][1]
        key = (program, defines)
        prog = self.renderer.load_program(SHADERS, program, defines)
        if key not in vaos or vaos[key].program is not prog:  # new, or F5 reloaded the shader
            if key in vaos:
                vaos[key].release()
            vaos[key] = self.ctx.vertex_array(prog, [(buf, "3f", "in_position")])
        return vaos[key]

    def _particle_buffer(self, devil: DevilFrame) -> moderngl.Buffer:
        """The devil's world positions (N x 3 float32), uploaded once per frame."""
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
            buf.write(devil.positions)
            self._uploaded[devil.entity] = frame
        return buf

    def _resolve_vao(self, fragment: str, define: str = "") -> moderngl.VertexArray:
        """A full-screen triangle with ``shaders/<fragment>.frag`` (``define``: a ``#define`` line's text after
        its ``#version`` line, a variant)."""
        vao = self._resolve.get((fragment, define))
        if vao is None:
            version, rest = (SHADERS / f"{fragment}.frag").read_text().split("\n", 1)
            source = f"{version}\n#define {define}\n{rest}" if define else f"{version}\n{rest}"
            prog = self.renderer.program((ENGINE_SHADERS / "fullscreen.vert").read_text(), source)
            vao = self._resolve[(fragment, define)] = self.ctx.vertex_array(prog, [])
        return vao

    def _bind_ball(self, program) -> None:
        """Bind the pseudo-particle offset table (:func:`ball_offsets` of the scene's seed, uploaded once) to
        ``program``'s ``BallOffsets`` block."""
        if self._ball is None or self._ball[0] != self._seed:
            if self._ball is not None:
                self._ball[1].release()
            self._ball = (self._seed, self.ctx.buffer(ball_offsets(self._seed).tobytes()))
        program["BallOffsets"].binding = BALL_BINDING
        self._ball[1].bind_to_uniform_block(BALL_BINDING)

    def _coverage_image(self, entity: int, view: View, words: int) -> moderngl.Texture:
        """The persistent coverage words of a dust devil in a view: (width, height x words) r32ui, created zero;
        the resolve leaves it zero again every frame."""
        size = (view.width, view.height * words)
        key = (entity, view.name)
        held = self._coverage.get(key)
        if held is not None and held[0] == size:
            return held[1]
        if held is not None:
            self.release_texture(held[1])
        texture = self.ctx.texture(size, 1, np.zeros(size[0] * size[1], np.uint32).tobytes(), dtype="u4")
        self._coverage[key] = (size, texture)
        self._unresolved.discard(key)
        return texture

    def _compute(self, point_side: int) -> moderngl.ComputeShader:
        """``shaders/pbvr_scatter.comp`` for points of ``point_side`` pixels (compiled once per side by the
        renderer, which reloads it with F5)."""
        return self.renderer.load_compute(SHADERS, "pbvr_scatter", (f"POINT_SIDE {point_side}",
                                                                    f"LOCAL_SIZE {COMPUTE_GROUP}"))

    def use_scatter(self, repeats: int) -> bool:
        """Whether R repeats take the scatter path (R <= 64 and the context compiles its shaders; probed once, and
        logged): as a compute shader (GL 4.3) if it can, else in the vertex stage (GL 4.2)."""
        if self.scatter is None:
            self.scatter, self.compute, reasons = False, False, []
            if self.ctx.version_code >= 430:
                try:
                    self._compute(1)
                    self._resolve_vao("pbvr_coverage", "WORDS 1")
                    self.scatter = self.compute = True
                except (RuntimeError, moderngl.Error) as exc:
                    reasons.append(str(exc))
            if not self.scatter and self.ctx.version_code >= 420:
                try:
                    self.renderer.load_program(SHADERS, "pbvr_scatter")
                    self._resolve_vao("pbvr_coverage", "WORDS 1")
                    self.scatter = True
                except (RuntimeError, moderngl.Error) as exc:  # e.g. no image stores in the vertex stage
                    reasons.append(str(exc))
            path = ("scatter (compute shader)" if self.compute else "scatter (vertex stage)" if self.scatter
                    else "GL 3.3 slab (the same ensemble, slower)")
            LOG.info("dust_devil: PBVR takes the %s path (GL %d)%s", path, self.ctx.version_code,
                     "".join(f"; {r}" for r in reasons))
        return self.scatter and repeats <= MAX_SCATTER_REPEATS

    @property
    def path(self) -> str:
        """The PBVR path probed: 'compute', 'vertex' (both scatter), 'slab', or '-' before the first PBVR frame."""
        if self.scatter is None:
            return "-"
        return "compute" if (self.scatter and self.compute) else "vertex" if self.scatter else "slab"

    # ------------------------------------------------------------------------------ passes
    def add_passes(self, graph, view: View, data: list[DevilFrame]) -> None:
        for devil in data:
            # point_size is in window pixels: at a lower render scale the points are as many fewer of the view's
            # pixels, so that each covers the same share of the image and the dust keeps its density (below one
            # pixel the scatter covers a pixel with the probability of the point's area; GL's points stay 1 px)
            devil = replace(devil, point_size=view.view_pixels(devil.point_size))
            if not devil.pbvr:
                self._add_points(graph, view, devil)
            elif self.use_scatter(devil.repeats):
                self._add_scatter(graph, view, devil)
            else:
                self._add_slab(graph, view, devil)

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

    # ------------------------------------------------------------------------- scatter path
    def _add_scatter(self, graph, view: View, devil: DevilFrame) -> None:
        prefix = f"dust_devil.{devil.entity}"
        words = coverage_words(devil.repeats)
        rect = screen_rect(devil.positions, view.view_proj, view.width, view.height, devil.radius,
                           devil.point_size)
        key = (devil.entity, view.name)
        # persistent and zero at the start of every frame (the resolve zeroes what it reads): no clear pass
        h: dict[str, Any] = {"cov": graph.import_resource(f"{prefix}.coverage.{view.name}",
                                                          self._coverage_image(devil.entity, view, words))}
        self.declared_repeats[key] = devil.repeats

        def accumulate_setup(b):
            b.read(view.depth)
            h["cov"] = b.write(h["cov"])

        def accumulate(pc):
            if rect is None:
                return
            ctx = self.ctx
            coverage = pc.get(h["cov"])
            if key in self._unresolved:  # an earlier frame scattered but never resolved (it raised): start empty
                coverage.write(np.zeros(coverage.width * coverage.height, np.uint32).tobytes())
            self._unresolved.add(key)
            ctx.memory_barrier()  # the last resolve's image stores (zeroes) before this pass's loads
            self.renderer.framebuffer(coverage).use()  # not the view's: its depth is sampled here
            scene_depth = pc.get(view.depth)
            compare = scene_depth.compare_func
            if compare:  # the engine's depth targets sample raw values already; no texture state change then
                scene_depth.compare_func = ""
            scene_depth.use(0)
            coverage.bind_to_image(0, read=True, write=True, format=GL_R32UI)
            uniforms = dict(view_proj=view.view_proj.T.copy(), sub_particles=devil.sub_particles,
                            frame_key=self.frame_key, radius=devil.radius,
                            point_size=devil.point_size, view_size=(view.width, view.height), scene_depth=0)
            side = max(1, math.ceil(devil.point_size))  # POINT_SIDE: pixels a point spans per axis (under 1: 0 or 1)
            if self.compute:
                n = len(devil.positions)
                shader = self._compute(side)
                self._particle_buffer(devil).bind_to_storage_buffer(0)
                self._bind_ball(shader)
                set_uniforms(shader, particles=n, repeats=devil.repeats, **uniforms)
                shader.run((n + COMPUTE_GROUP - 1) // COMPUTE_GROUP)
            else:
                vao = self._vao(devil, "pbvr_scatter", (f"POINT_SIDE {side}",))
                self._bind_ball(vao.program)
                set_uniforms(vao.program, **uniforms)
                ctx.enable(moderngl.RASTERIZER_DISCARD)
                vao.render(moderngl.POINTS, vertices=len(devil.positions),
                           instances=devil.repeats * devil.sub_particles)
                ctx.disable(moderngl.RASTERIZER_DISCARD)
            ctx.memory_barrier()  # the resolve reads the words through image loads
            if compare:
                scene_depth.compare_func = compare

        graph.add_pass(f"{prefix}.pbvr_accumulate.{view.name}", accumulate_setup, accumulate)

        def resolve_setup(b):
            h["cov"] = b.write(h["cov"])  # reads the words and zeroes them (image loads and stores)
            write_view_color(b, view, rect if rect is not None else (0, 0, 0, 0))  # its scissor

        def resolve(pc):
            if rect is None:
                return
            fbo = self.renderer.framebuffer(pc.get(view.color))
            fbo.use()
            fbo.scissor = rect  # the pixels the cloud can reach; the rest keeps the scene
            ctx = self.ctx
            ctx.disable(moderngl.DEPTH_TEST)
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA
            pc.get(h["cov"]).bind_to_image(0, read=True, write=True, format=GL_R32UI)
            vao = self._resolve_vao("pbvr_coverage", f"WORDS {words}")
            set_uniforms(vao.program, view_height=view.height, color=devil.color,
                         inv_repeats=1.0 / devil.repeats)
            vao.render(moderngl.TRIANGLES, vertices=3)
            ctx.disable(moderngl.BLEND)
            fbo.scissor = None
            self._unresolved.discard(key)

        graph.add_pass(f"{prefix}.pbvr_resolve.{view.name}", resolve_setup, resolve)

    # ---------------------------------------------------------------------------- slab path
    def _add_slab(self, graph, view: View, devil: DevilFrame) -> None:
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

        def accumulate_setup(b):
            b.read(view.depth)
            h["acc"] = b.write(h["acc"])
            h["slab"] = b.write(h["slab"])

        graph.add_pass(f"{prefix}.pbvr_accumulate.{view.name}", accumulate_setup,
                       self._slab_execute(view, devil, h))

        def resolve_setup(b):
            b.read(h["acc"])
            view.color = b.write(view.color)

        def resolve(pc):
            fbo = self.renderer.framebuffer(pc.get(view.color))
            fbo.use()
            ctx = self.ctx
            ctx.disable(moderngl.DEPTH_TEST)
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA
            vao = self._resolve_vao("resolve")
            pc.get(h["acc"]).use(0)
            set_uniforms(vao.program, accumulation=0, inv_repeats=1.0 / devil.repeats)
            vao.render(moderngl.TRIANGLES, vertices=3)
            ctx.disable(moderngl.BLEND)

        graph.add_pass(f"{prefix}.pbvr_resolve.{view.name}", resolve_setup, resolve)

    def _slab_execute(self, view: View, devil: DevilFrame, h: dict):
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
            self._bind_ball(vao.program)
            key = self.frame_key
            for r in range(devil.repeats):
                set_uniforms(vao.program, view_proj=view.view_proj.T.copy(), sub_particles=devil.sub_particles,
                             repeat_index=r, frame_key=key, radius=devil.radius,
                             slab_depth=slab_depth(r, devil.repeats), point_size=devil.point_size,
                             color=devil.color, scene_depth=0)
                vao.render(moderngl.POINTS, vertices=len(devil.positions), instances=devil.sub_particles)
            scene_depth.compare_func = compare
            ctx.disable(moderngl.BLEND | moderngl.PROGRAM_POINT_SIZE)

        return execute

    def release(self) -> None:
        for buf, vaos in self._buffers.values():
            for vao in vaos.values():
                vao.release()
            buf.release()
        self._buffers.clear()
        self._uploaded.clear()
        for vao in self._resolve.values():
            vao.release()
        self._resolve.clear()
        for _, texture in self._coverage.values():
            self.release_texture(texture)
        self._coverage.clear()
        self._unresolved.clear()
        if self._ball is not None:
            self._ball[1].release()
            self._ball = None


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

    def static_key(self, view: View, data: np.ndarray) -> Any:
        """The spheres' matrices and colours: unchanged while the field box is not dragged, so a still camera
        copies them back with the terrain and the sky (the renderer's static layer) instead of drawing them.
        None when there are none (no passes either)."""
        return data.tobytes() if len(data) else None

    def _vao(self, count: int) -> tuple[moderngl.VertexArray, moderngl.Buffer]:
        needed = max(count, 9) * self.INSTANCE_FLOATS * 4
        prog = self.renderer.load_program(ENGINE_SHADERS, "mesh", ("FOG",))  # small: fog always compiled in
        if self._gl is None or self._gl[1].size < needed or self._gl[0].program is not prog:  # or F5 reloaded it
            self.release()
            verts, idx = primitive("sphere", MARKER_SEGMENTS)
            inst = self.ctx.buffer(reserve=needed)
            vbo, ibo = self.ctx.buffer(verts.tobytes()), self.ctx.buffer(idx.tobytes())
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
